"""Typed configs of the multi-view model: the Text2World networks plus the multi-view parts."""

from __future__ import annotations

import dataclasses
from typing import Literal

from drivewm.config import above, at_least, in_range, require
from drivewm.diffusion.denoiser import EDMConfig
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.errors import DrivewmError
from drivewm.text import TextConfig


@dataclasses.dataclass
class MultiViewConfig:
    """What the multi-view model adds to its Text2World parent (all new parameters start at zero effect)."""

    cross_view: Literal["joint", "neighbors"] = "neighbors"
    """Cross-view attention: every view reads all views (``joint``) or itself and its nearest cameras by
    viewing direction (``neighbors``: memory and compute grow with V * (neighbors + 1), not V^2)."""
    neighbors: int = 2
    """Cameras besides itself that each view attends to in ``neighbors`` mode."""
    camera_cond: bool = True
    """Add per-token Plucker-ray embeddings computed from K and T_ego_from_cam."""
    camera_width: int = 128
    """Hidden width of the Plucker-ray MLP."""
    moving_camera_rays: bool = False
    """With a trajectory, each latent frame's rays are those of the cameras at the ego pose of that
    frame, in the first frame's ego frame (per-frame Plucker camera control as in CameraCtrl, He et al.
    2024), so the trajectory also conditions every token locally, not only through the global MLP."""
    frame_motion: bool = True
    """With a trajectory, add an embedding of the ego's pose and step at every token frame to all of
    that frame's tokens (drivewm.multiview.frame_motion): the per-frame motion without moving the
    rays (set ``moving_camera_rays`` false with it, so a token's rays only say where it looks)."""
    warp_ground_m: float = 100.0
    """The flat-world warp of the opt-in post-steps (drivewm.views.warp) follows rays that meet the road
    within this distance (m) to the road plane and all others to infinity; 0 = every ray at infinity
    (a pure-rotation warp)."""
    ray_scale_m: float = 10.0
    """Ray moments (o x d, metres) are divided by this before the ray MLP."""
    temporal_compression: int = 4
    """Video frames per latent frame after the first (the tokenizer's): latent frame i shows frame i * this."""
    trajectory_waypoints: int = 16
    """Future ego waypoints (ClipMeta.trajectory_ego) the model is conditioned on; 0 = none."""
    trajectory_scale_m: float = 20.0
    """Waypoints are divided by this (m) before the trajectory MLP, so its inputs are O(1)."""
    trajectory_dt_s: float = 0.1
    """Spacing of the waypoints (s), from the training clips (ClipMeta.trajectory_dt_s)."""
    speed_mps: float = 20.49
    """Default speed of the named trajectories (set to the training clips' median initial speed)."""
    trajectory_width: int = 256
    """Hidden width of the trajectory MLP."""
    trajectory_dropout: float = 0.1
    """Fraction of training clips whose trajectory is dropped (static-rig rays, no waypoint embedding),
    so the model also learns the trajectory-free prediction that trajectory guidance contrasts with."""
    video2world_prob: float = 0.5
    """Fraction of training steps conditioned on the first ``edm.cond_frames`` clean latent frames
    (the rest are plain text-to-multi-view steps, so one model does both)."""
    layout: Literal["none", "tokens", "controlnet"] = "none"
    """How the drive's layout (its boxes and road lines drawn into every camera, drivewm.layout.render,
    coded by the tokenizer) steers the model (drivewm.multiview.layout_encoder): not at all, its
    embedding added to the patch tokens (``tokens``), or fed to a ControlNet branch of the DiT's first
    ``layout_control_depth`` blocks (``controlnet``, drivewm.diffusion.dit.ControlBranch)."""
    layout_control_depth: int = 2
    """Blocks the ControlNet branch copies (``layout: controlnet``)."""
    layout_dropout: float = 0.1
    """Fraction of training clips whose layout is dropped (all views together), so the model also
    generates from text and trajectory alone."""

    def validate(self) -> None:
        require(self.cross_view in ("joint", "neighbors"), "cross_view", self.cross_view, "'joint' or 'neighbors'")
        at_least(self, 0, "neighbors", "trajectory_waypoints", "warp_ground_m", "speed_mps")
        at_least(self, 1, "camera_width", "trajectory_width", "temporal_compression")
        above(self, 0, "trajectory_scale_m", "trajectory_dt_s", "ray_scale_m")
        in_range(self, "video2world_prob", 0, 1)
        in_range(self, "trajectory_dropout", 0, 1, high_open=True)
        in_range(self, "layout_dropout", 0, 1, high_open=True)
        require(self.layout in ("none", "tokens", "controlnet"), "layout", self.layout, "none, tokens or controlnet")
        at_least(self, 1, "layout_control_depth")


#: Fields of experiments that did not ship, read from saved folders only when they are off.
RETIRED_FIELDS = {"warp_condition": False, "warped_noise": 0.0, "warp_walls_m": 0.0}


def retire_saved_fields(multiview: dict, where: str) -> dict:
    """A saved ``multiview`` section without :data:`RETIRED_FIELDS` (a DrivewmError when one is on: the
    folder's network needs a part drivewm no longer has)."""
    on = [k for k, off in RETIRED_FIELDS.items() if k in multiview and multiview[k] != off]
    if on:
        raise DrivewmError(f"{where}: trained with {on}, which drivewm no longer supports")
    return {k: v for k, v in multiview.items() if k not in RETIRED_FIELDS}


@dataclasses.dataclass
class MultiViewModelConfig:
    """The networks of a multi-view model folder (``model_type: multiview``)."""

    dit: DiTConfig = dataclasses.field(default_factory=DiTConfig)
    """The shared DiT backbone (its ``block_layers`` include ``cross_view_attn``)."""
    edm: EDMConfig = dataclasses.field(default_factory=EDMConfig)
    """Preconditioning, loss and Video2World frames (``cond_frames``)."""
    text: TextConfig = dataclasses.field(default_factory=TextConfig)
    """Caption encoder (frozen), the parent's."""
    multiview: MultiViewConfig = dataclasses.field(default_factory=MultiViewConfig)
    """Cross-view attention, camera and trajectory conditioning."""


def with_layout_control(cfg: MultiViewModelConfig) -> MultiViewModelConfig:
    """``cfg`` with the DiT's ControlNet branch as deep as its multi-view config asks (``layout:
    controlnet``), or without one."""
    mv = cfg.multiview
    depth = min(mv.layout_control_depth, cfg.dit.depth) if mv.layout == "controlnet" else 0
    return dataclasses.replace(cfg, dit=dataclasses.replace(cfg.dit, control_depth=depth))
