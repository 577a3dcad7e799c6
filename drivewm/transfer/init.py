"""Initialise a transfer model from a Text2World model folder so that it starts as the parent.

Every DiT parameter of the parent is copied; the new parts (the source projection and the last
layer of the condition MLP) are zero-initialised, so the step-0 model's prediction is the
parent's for any source and condition (tests/transfer/test_transfer_model.py).
"""

from __future__ import annotations

import dataclasses

from drivewm.diffusion.text2world import Text2World
from drivewm.errors import DrivewmError
from drivewm.transfer.config import TransferConfig, TransferModelConfig
from drivewm.transfer.model import Transfer


def from_text2world(
    parent: Text2World, transfer: TransferConfig, p_mean: float | None = None, name: str = ""
) -> Transfer:
    """A transfer model equal to ``parent`` (its DiT, EDM and text encoder); ``p_mean`` (optional)
    replaces the training noise distribution's mean ln(sigma); ``name`` records the parent folder."""
    edm = dataclasses.replace(parent.cfg.edm, cond_frames=0)  # transfer gives the whole source, not first frames
    edm = edm if p_mean is None else dataclasses.replace(edm, p_mean=p_mean)
    cfg = TransferModelConfig(parent.cfg.dit, edm, parent.cfg.text, transfer)
    model = Transfer(cfg, dataclasses.replace(parent.latent), name)
    state = model.net.state_dict()
    for key, value in parent.dit.state_dict().items():
        ours = f"denoiser.backbone.{key}"
        if ours not in state or state[ours].shape != value.shape:
            raise DrivewmError(f"init: parent parameter {key} {tuple(value.shape)} has no place in the transfer model")
        state[ours] = value.clone()
    model.net.load_state_dict(state)
    return model
