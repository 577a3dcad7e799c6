"""The multi-view model: the Text2World DiT (shared by all views, folded into the batch as (B V))
plus cross-view attention, camera (Plucker-ray) and ego-trajectory conditioning, and Video2World.

:class:`MultiViewNet` is the trainable module ``forward(x, sigma, cond) -> denoised``: it turns the
raw conditioning (rays, waypoints) into the DiT's ``extra_token_cond`` / ``extra_global_cond`` and
calls the EDM denoiser. :class:`MultiView` is the inference bundle and model folder
(``config.json`` with ``model_type: "multiview"`` + ``model.safetensors``).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch
from einops import rearrange, repeat
from torch import nn

from drivewm.config import from_dict, to_dict
from drivewm.device import resolve_device
from drivewm.diffusion.blocks import register_sublayer
from drivewm.diffusion.data import denormalize_latents, normalize_latents
from drivewm.diffusion.denoiser import Conditioning, EDMDenoiser
from drivewm.diffusion.dit import DiT
from drivewm.diffusion.dit_config import upgrade_saved_config
from drivewm.diffusion.sampling import sample
from drivewm.diffusion.text2world import LatentInfo, read_latent_info
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig, rig_from_dict
from drivewm.multiview.camera import CameraEncoder
from drivewm.multiview.config import MultiViewModelConfig, retire_saved_fields
from drivewm.multiview.cross_view import SUBLAYER_NAME, CrossViewAttention, view_neighbors
from drivewm.multiview.frame_motion import FrameMotionEncoder, frame_motion_features
from drivewm.multiview.layout_encoder import LayoutEncoder
from drivewm.multiview.trajectories import poses_from_waypoints
from drivewm.multiview.trajectory_encoder import TrajectoryEncoder
from drivewm.text import build_text_encoder
from drivewm.train.checkpoint import load_model_folder, load_weights, save_model_folder
from drivewm.views.rays import moving_token_rays, plucker_rays, token_rays

MODEL_TYPE = "multiview"


@dataclasses.dataclass
class MultiViewConditioning(Conditioning):
    """:class:`Conditioning` of (B V) folded views plus the raw camera and trajectory inputs."""

    rays: torch.Tensor | None = None
    """(B V, N, 6) Plucker coordinates (ego frame) of every token's patch centre."""
    static_rays: torch.Tensor | None = None
    """(B V, N, 6) the rays of the rig standing still (= ``rays`` without a moving-camera trajectory):
    what a view is conditioned on when its trajectory is dropped."""
    trajectory: torch.Tensor | None = None
    """(B V, W, 3) future ego waypoints (m) in the first frame's ego frame (repeated per view)."""
    frame_motion: torch.Tensor | None = None
    """(B V, t, F) the ego's pose and step at every token frame (drivewm.multiview.frame_motion);
    None = no per-frame motion conditioning."""
    trajectory_keep: torch.Tensor | None = None
    """(B V,) bool: False = this view's trajectory is dropped (training dropout, or the trajectory-free
    branch of trajectory guidance); None = every trajectory kept."""
    layout: torch.Tensor | None = None
    """(B V, c, t, h, w) the layout video's latents (drivewm.layout.render, coded by the clip's
    tokenizer), normalised as the clip's; None = no layout (drivewm.multiview.layout_encoder)."""
    layout_keep: torch.Tensor | None = None
    """(B V,) bool: False = this view's layout is dropped; None = every layout kept."""

    def drop_trajectory(self, keep: torch.Tensor) -> MultiViewConditioning:
        """A copy where views with ``keep`` (B V,) False see no trajectory."""
        old = self.trajectory_keep if self.trajectory_keep is not None else torch.ones_like(keep)
        return dataclasses.replace(self, trajectory_keep=old & keep)

    def without_trajectory(self) -> MultiViewConditioning:
        """The same conditioning with every trajectory dropped (trajectory guidance's other branch)."""
        return self.drop_trajectory(torch.zeros(self.fps.shape[0], dtype=torch.bool, device=self.fps.device))


class MultiViewNet(nn.Module):
    """EDM denoiser around the shared DiT, with the camera and trajectory encoders.

    ``forward(x (B V, c, t, h, w), sigma (B V,), cond: MultiViewConditioning) -> denoised (B V, c, t, h, w)``.
    """

    def __init__(self, cfg: MultiViewModelConfig):
        super().__init__()
        cfg.multiview.validate()
        self.cfg = cfg
        register_sublayer(SUBLAYER_NAME, CrossViewAttention)  # the one sub-layer the multi-view DiT adds
        self.denoiser = EDMDenoiser(DiT(cfg.dit), cfg.edm, cfg.dit.cond_mask_channel)
        mv, dim = cfg.multiview, cfg.dit.hidden_dim
        self.camera_encoder = CameraEncoder(dim, mv.camera_width, mv.ray_scale_m) if mv.camera_cond else None
        self.motion_encoder = FrameMotionEncoder(dim, mv.camera_width) if mv.frame_motion else None
        self.trajectory_encoder = (
            TrajectoryEncoder(mv.trajectory_waypoints, dim, mv.trajectory_width, mv.trajectory_scale_m)
            if mv.trajectory_waypoints
            else None
        )
        if (mv.layout == "controlnet") != (cfg.dit.control_depth > 0):
            raise DrivewmError(
                f"multiview.layout {mv.layout!r} with dit.control_depth {cfg.dit.control_depth}: "
                "build the config with drivewm.multiview.config.with_layout_control"
            )
        d = cfg.dit
        self.layout_encoder = (
            LayoutEncoder(d.in_channels, dim, d.patch_size, d.patch_t) if mv.layout != "none" else None
        )

    @property
    def dit(self) -> DiT:
        return self.denoiser.backbone

    def forward(self, x: torch.Tensor, sigma: torch.Tensor, cond: MultiViewConditioning) -> torch.Tensor:
        token_cond = global_cond = None
        keep = cond.trajectory_keep
        if self.camera_encoder is not None and cond.rays is not None:
            rays = cond.rays
            if keep is not None and cond.static_rays is not None:
                rays = torch.where(keep[:, None, None], rays, cond.static_rays)
            token_cond = self.camera_encoder(rays.to(x.dtype))  # (B V, N, D)
        if self.motion_encoder is not None and cond.frame_motion is not None:
            motion = self.motion_encoder(cond.frame_motion.to(x.dtype))  # (B V, t, D)
            if keep is not None:
                motion = motion * keep[:, None, None].to(motion.dtype)
            tokens_per_frame = x.shape[-2] * x.shape[-1] // self.cfg.dit.patch_size**2  # tokens are (t, h, w)
            motion = motion.repeat_interleave(tokens_per_frame, dim=1)
            token_cond = motion if token_cond is None else token_cond + motion
        if self.trajectory_encoder is not None and cond.trajectory is not None:
            global_cond = self.trajectory_encoder(cond.trajectory.to(x.dtype))  # (B V, D)
            if keep is not None:
                global_cond = global_cond * keep[:, None].to(global_cond.dtype)
        control = None
        if self.layout_encoder is not None:
            layout = self.layout_encoder(cond.layout, cond.layout_keep, x)  # (B V, N, D)
            if self.cfg.multiview.layout == "tokens":
                token_cond = layout if token_cond is None else token_cond + layout
            else:
                control = layout
        return self.denoiser(
            x,
            sigma,
            dataclasses.replace(
                cond, extra_token_cond=token_cond, extra_global_cond=global_cond, control_tokens=control
            ),
        )


class MultiView:
    """Inference bundle: ``sample_latents(rig, view_captions, trajectories, seeds) -> (B, V, c, t, h, w)``."""

    def __init__(self, cfg: MultiViewModelConfig, latent: LatentInfo):
        self.cfg = cfg
        self.latent = latent
        self.text_encoder = build_text_encoder(cfg.text)
        self.net = MultiViewNet(cfg).eval()
        self.device = torch.device("cpu")

    def to(self, device: str | torch.device) -> MultiView:
        """Run sampling on ``device`` (``auto``: CUDA when available); noise stays seeded on the CPU."""
        self.device = resolve_device(device)
        self.net.to(self.device)
        return self

    def save_pretrained(self, path: str | Path, state: dict[str, torch.Tensor] | None = None) -> None:
        """Write the model folder (``state`` defaults to the network's current weights)."""
        state = state if state is not None else self.net.state_dict()
        save_model_folder(path, MODEL_TYPE, to_dict(self.cfg), state, {"latent": to_dict(self.latent)})

    @classmethod
    def from_pretrained(cls, path: str | Path) -> MultiView:
        info, state = load_model_folder(path, MODEL_TYPE)
        where = f"{Path(path) / 'config.json'}"
        saved = upgrade_saved_config(info["config"])
        if isinstance(saved.get("multiview"), dict):
            saved["multiview"] = retire_saved_fields(saved["multiview"], where)
        config = from_dict(MultiViewModelConfig, saved, where)
        model = cls(config, read_latent_info(info, path, config.dit))
        load_weights(model.net, state, path)
        return model

    @property
    def training_rig(self) -> Rig:
        return rig_from_dict(self.latent.rig, "model rig")

    def token_grid(self) -> tuple[int, int, int]:
        """(t, h, w) token grid of one view's latents."""
        _, t, h, w = self.latent.latent_shape
        d = self.cfg.dit
        return t // d.patch_t, h // d.patch_size, w // d.patch_size

    def conditioning(
        self, rig: Rig, view_captions: list[list[str]], trajectories: np.ndarray | None, fps: float | None = None
    ) -> MultiViewConditioning:
        """Conditioning of B clips of ``rig`` (V views): captions (B, V) strings, waypoints (B, W, 3) m."""
        return build_conditioning(self, rig, view_captions, trajectories, fps or self.latent.fps)

    @torch.no_grad()
    def sample_latents(
        self,
        rig: Rig,
        view_captions: list[list[str]],
        trajectories: np.ndarray | None,
        seeds: list[int],
        steps: int = 35,
        guidance: float = 7.0,
        sampler: str = "heun",
        cond_latents: torch.Tensor | None = None,
        fps: float | None = None,
        trajectory_guidance: float = 1.0,
        start_latents: torch.Tensor | None = None,
        start_sigma: float | None = None,
        guidance_interval: tuple[float, float] | None = None,
        layout_latents: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Raw (denormalised) latents (B, V, c, t, h, w) of B clips; clip b's noise from ``seeds[b]``.

        ``layout_latents`` (B, V, c, t, h, w) raw: the tokenizer's code of each clip's layout video in
        the rig's cameras (a model trained with ``multiview.layout``; None = no layout).

        ``cond_latents`` (B, V, c, t, h, w) raw latents whose first ``edm.cond_frames`` latent frames
        are kept (Video2World); None = generate every frame. ``trajectory_guidance`` w > 1 weighs the
        trajectory's effect w times (drivewm.diffusion.sampling.guided; twice the network evaluations).
        ``start_latents`` (B, V, c, t, h, w) raw: sample from them noised to ``start_sigma`` (SDEdit;
        drivewm.generate.reproject), not from pure noise. ``guidance_interval`` (lo, hi): both guidances
        only at sigma in (lo, hi] (drivewm.diffusion.sampling; None: at every sigma).
        """
        v = len(rig.cameras)
        cond = self.conditioning(rig, view_captions, trajectories, fps)
        mean, std = self._stats()
        if cond_latents is not None:
            z = self._normalized(cond_latents, mean, std)
            cond = dataclasses.replace(cond, cond_latents=z, cond_frames=max(1, self.cfg.edm.cond_frames))
        if layout_latents is not None:
            if self.cfg.multiview.layout == "none":
                raise DrivewmError("this multi-view model was not trained with a layout (multiview.layout: none)")
            cond = dataclasses.replace(cond, layout=self._normalized(layout_latents, mean, std))
        start = (
            None if start_latents is None else self._normalized(start_latents, mean, std).reshape(start_latents.shape)
        )
        shape = (v, *self.latent.latent_shape)  # the views of a clip share its seed, folded as (B V)
        trajectory_guidance = trajectory_guidance if trajectories is not None else 1.0
        x = sample(
            self.net,
            cond,
            shape,
            seeds,
            steps,
            guidance,
            sampler,
            trajectory_guidance,
            self.device,
            start=start,
            start_sigma=start_sigma,
            guidance_interval=guidance_interval,
        )
        return denormalize_latents(x, mean, std, self.cfg.edm.sigma_data)  # (B, V, c, t, h, w)

    def _normalized(self, latents: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
        """Raw (B, V, c, t, h, w) -> normalised (B V, c, t, h, w), as the network sees them."""
        return normalize_latents(
            rearrange(latents.cpu(), "b v c t h w -> (b v) c t h w"), mean, std, self.cfg.edm.sigma_data
        )

    def _stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.tensor(self.latent.latent_mean), torch.tensor(self.latent.latent_std)


def build_conditioning(
    model: MultiView, rig: Rig, view_captions: list[list[str]], trajectories: np.ndarray | None, fps: float
) -> MultiViewConditioning:
    """Text, rays, waypoints and view neighbours of B clips of ``rig``, folded to (B V)."""
    b, v = len(view_captions), len(rig.cameras)
    if any(len(caps) != v for caps in view_captions):
        raise DrivewmError(f"need one caption per camera of rig {rig.name} ({v}) for every clip")
    mv = model.cfg.multiview
    emb, mask = model.text_encoder.encode([c for caps in view_captions for c in caps])  # (B V, L, text_dim)
    traj = None
    if trajectories is not None:
        traj = repeat(torch.as_tensor(np.asarray(trajectories), dtype=torch.float32), "b w c -> (b v) w c", v=v)
    static_rays = clip_rays(model, rig, b, None, fps)
    rays = (
        static_rays
        if trajectories is None or not mv.moving_camera_rays
        else clip_rays(model, rig, b, trajectories, fps)
    )
    motion = None
    if mv.frame_motion and trajectories is not None:
        motion = repeat(clip_frame_motion(model, trajectories, fps), "b t f -> (b v) t f", v=v)
    return MultiViewConditioning(
        emb,
        mask,
        torch.full((b * v,), float(fps)),
        num_views=v,
        view_neighbors=view_neighbors(rig, mv.cross_view, mv.neighbors),
        rays=rays,
        static_rays=static_rays,
        trajectory=traj,
        frame_motion=motion,
    )


def clip_frame_motion(model: MultiView, trajectories: np.ndarray, fps: float) -> torch.Tensor:
    """(B, t, F) ego motion at every token frame of B clips (drivewm.multiview.frame_motion)."""
    t, _, _ = model.token_grid()
    mv = model.cfg.multiview
    feats = [
        frame_motion_features(wp, t, mv.trajectory_dt_s, token_fps(model, fps), mv.trajectory_scale_m)
        for wp in np.asarray(trajectories)
    ]
    return torch.from_numpy(np.stack(feats))


def token_fps(model: MultiView, fps: float) -> float:
    """Token frames per second of a clip at ``fps``: token frame i shows video frame i * tc * patch_t."""
    return fps / (model.cfg.multiview.temporal_compression * model.cfg.dit.patch_t)


def clip_rays(model: MultiView, rig: Rig, b: int, trajectories: np.ndarray | None, fps: float) -> torch.Tensor:
    """(B V, N, 6) Plucker rays of every token: the static rig's, or with a trajectory (and
    ``moving_camera_rays``) the rig's at each token frame's ego pose, in the first frame's ego frame."""
    t, h, w = model.token_grid()
    mv = model.cfg.multiview
    rays_hw = plucker_rays(rig, (h, w))  # (V, h*w, 6) in the ego frame
    if trajectories is None or not mv.moving_camera_rays:
        return repeat(token_rays(rays_hw, t), "v n c -> (b v) n c", b=b)
    poses = [
        torch.from_numpy(poses_from_waypoints(wp, t, mv.trajectory_dt_s, token_fps(model, fps)))
        for wp in np.asarray(trajectories)
    ]
    return torch.cat([moving_token_rays(rays_hw, T).float() for T in poses])
