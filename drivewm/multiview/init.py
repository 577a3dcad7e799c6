"""Initialise a multi-view model from a Text2World model folder so that it starts as the parent per view.

Every parameter of the parent is copied; the new ones are built so that they add exactly zero:
the cross-view sub-layer's output projection, the last layers of the camera and trajectory MLPs
(all zero-initialised) and, when Video2World adds a mask input channel to a parent without one,
zero patch-embedding columns for that channel. Hence the zero-step model equals the parent on
every view (tests/multiview/test_multiview_model.py).
"""

from __future__ import annotations

import dataclasses

import torch

from drivewm.diffusion.text2world import Text2World
from drivewm.errors import DrivewmError
from drivewm.multiview.config import MultiViewConfig, MultiViewModelConfig, with_layout_control
from drivewm.multiview.cross_view import SUBLAYER_NAME
from drivewm.multiview.model import MultiView


def multiview_config(parent: Text2World, mv: MultiViewConfig, cond_frames: int) -> MultiViewModelConfig:
    """The parent's networks with ``cross_view_attn`` inserted after in-view (joint or self) attention
    and ``cond_frames`` Video2World latent frames (which need the mask input channel)."""
    layers = list(parent.cfg.dit.block_layers)
    if SUBLAYER_NAME not in layers:
        in_view = [i for i, name in enumerate(layers) if name in ("joint_attn", "self_attn")]
        layers.insert(in_view[0] + 1 if in_view else 0, SUBLAYER_NAME)
    dit = dataclasses.replace(
        parent.cfg.dit, block_layers=layers, cond_mask_channel=parent.cfg.dit.cond_mask_channel or cond_frames > 0
    )
    edm = dataclasses.replace(parent.cfg.edm, cond_frames=cond_frames)
    return with_layout_control(MultiViewModelConfig(dit, edm, parent.cfg.text, mv))


def widen_patch_embed(weight: torch.Tensor, target: torch.Tensor, patch_volume: int) -> torch.Tensor:
    """Parent patch-embedding weight (D, C*P) -> (D, (C+1)*P) with zero columns for the mask channel
    (patchify orders features channel-major, so the new channel's P columns come last)."""
    if weight.shape == target.shape:
        return weight
    if target.shape != (weight.shape[0], weight.shape[1] + patch_volume):
        raise DrivewmError(f"init: patch embedding {tuple(weight.shape)} cannot widen to {tuple(target.shape)}")
    return torch.cat([weight, torch.zeros(weight.shape[0], patch_volume, dtype=weight.dtype)], dim=1)


def from_text2world(parent: Text2World, mv: MultiViewConfig | None = None, cond_frames: int = 1) -> MultiView:
    """A multi-view model equal to ``parent`` per view (fresh new parameters, see module docstring)."""
    cfg = multiview_config(parent, mv or MultiViewConfig(), cond_frames)
    model = MultiView(cfg, dataclasses.replace(parent.latent))
    state = model.net.state_dict()
    d = cfg.dit
    for name, value in parent.dit.state_dict().items():
        key = f"denoiser.backbone.{name}"
        if key not in state:
            raise DrivewmError(f"init: parent parameter {name} has no place in the multi-view model")
        if name == "patch_embed.weight":
            value = widen_patch_embed(value, state[key], d.patch_t * d.patch_size**2)
        if value.shape != state[key].shape:
            raise DrivewmError(
                f"init: parent parameter {name} {tuple(value.shape)} != multi-view {tuple(state[key].shape)}"
            )
        state[key] = value.clone()
    state.update(control_copy(state, state))
    model.net.load_state_dict(state)
    return model


def control_copy(state: dict[str, torch.Tensor], added: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """A new ControlNet branch's blocks start as copies of the main blocks they shadow (Zhang et al.
    2023, sec. 3.1); their zero-initialised output projections keep the model as it was."""
    prefix, main = "denoiser.backbone.control.blocks.", "denoiser.backbone.blocks."
    return {k: state[main + k[len(prefix) :]].clone() for k in added if k.startswith(prefix)}
