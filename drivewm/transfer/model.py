"""The transfer model: the Text2World DiT conditioned on a source clip and a target condition.

:class:`TransferNet` is the trainable module ``forward(x, sigma, cond) -> denoised``: it turns the
source latents into per-token offsets (``extra_token_cond``, a zero-initialised patch projection,
drivewm.diffusion.warp_encoder) and the target's weather / time of day into a global offset
(``extra_global_cond``, :class:`ConditionEncoder`), then calls the parent's EDM denoiser. Views are
folded into the batch and transferred each on its own, so any rig works; each view keeps its own
source's geometry, hence the views stay consistent with each other. :class:`Transfer` is the
inference bundle and the model folder (``config.json`` with ``model_type: "transfer"``).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch
from torch import nn

from drivewm.config import from_dict, to_dict
from drivewm.device import resolve_device
from drivewm.diffusion.data import denormalize_latents, normalize_latents
from drivewm.diffusion.denoiser import Conditioning, EDMDenoiser
from drivewm.diffusion.dit import DiT
from drivewm.diffusion.dit_config import upgrade_saved_config
from drivewm.diffusion.sampling import sample
from drivewm.diffusion.text2world import LatentInfo, read_latent_info
from drivewm.diffusion.warp_encoder import WarpEncoder
from drivewm.model_folders import resolve_model_folder, resolve_reference
from drivewm.text import build_text_encoder
from drivewm.train.checkpoint import load_model_folder, load_weights, save_model_folder
from drivewm.transfer.condition_encoder import ConditionEncoder, condition_indices
from drivewm.transfer.config import TransferModelConfig
from drivewm.transfer.retarget import TargetCondition

MODEL_TYPE = "transfer"


@dataclasses.dataclass
class TransferConditioning(Conditioning):
    """:class:`Conditioning` plus the source clip and the structured target condition, batch-first."""

    source: torch.Tensor | None = None
    """(B, C, T, H, W) normalised source latents (the clip to transfer)."""
    weather: torch.Tensor | None = None
    """(B,) long target weather index (drivewm.transfer.condition_encoder; 0 = not given)."""
    time_of_day: torch.Tensor | None = None
    """(B,) long target time-of-day index (0 = not given)."""

    def drop_text(self, keep: torch.Tensor) -> TransferConditioning:
        """Samples with ``keep`` (B,) False lose their target condition: caption and fields (never the source)."""
        out = super().drop_text(keep)
        if self.weather is None:
            return out
        k = keep.to(self.weather.device).long()
        return dataclasses.replace(out, weather=self.weather * k, time_of_day=self.time_of_day * k)

    def unconditional(self) -> TransferConditioning:
        """The source without any target condition (classifier-free guidance's other branch)."""
        return self.drop_text(torch.zeros(self.text_mask.shape[0], dtype=torch.bool, device=self.text_mask.device))


class TransferNet(nn.Module):
    """``forward(x (B, c, t, h, w), sigma (B,), cond: TransferConditioning) -> denoised (B, c, t, h, w)``."""

    def __init__(self, cfg: TransferModelConfig):
        super().__init__()
        cfg.transfer.validate()
        self.cfg = cfg
        d, tr = cfg.dit, cfg.transfer
        self.denoiser = EDMDenoiser(DiT(d), cfg.edm, d.cond_mask_channel)
        self.source_encoder = (
            WarpEncoder(d.in_channels, d.hidden_dim, d.patch_size, d.patch_t) if tr.source == "channels" else None
        )
        self.condition_encoder = ConditionEncoder(d.hidden_dim, tr.condition_width) if tr.condition_fields else None

    @property
    def dit(self) -> DiT:
        return self.denoiser.backbone

    def forward(self, x: torch.Tensor, sigma: torch.Tensor, cond: TransferConditioning) -> torch.Tensor:
        token_cond = global_cond = None
        if self.source_encoder is not None and cond.source is not None:
            src = cond.source.to(x.dtype) / self.cfg.edm.sigma_data  # unit variance, as the DiT sees its input
            given = torch.ones_like(src[:, :1])  # (B, 1, T, H, W): the source is given everywhere
            token_cond = self.source_encoder(torch.cat([src, given], dim=1))  # (B, N, D)
        if self.condition_encoder is not None and cond.weather is not None:
            global_cond = self.condition_encoder(cond.weather, cond.time_of_day)  # (B, D)
        return self.denoiser(
            x, sigma, dataclasses.replace(cond, extra_token_cond=token_cond, extra_global_cond=global_cond)
        )


class Transfer:
    """Inference bundle: ``transfer_latents(source, captions, targets, seeds) -> (B, c, t, h, w)``."""

    def __init__(self, cfg: TransferModelConfig, latent: LatentInfo, parent: str = ""):
        self.cfg = cfg
        self.latent = latent
        self.parent = parent  # the Text2World folder it was post-trained from (for the record)
        self.text_encoder = build_text_encoder(cfg.text)
        self.net = TransferNet(cfg).eval()
        self.device = torch.device("cpu")

    def to(self, device: str | torch.device) -> Transfer:
        """Run sampling on ``device`` (``auto``: CUDA when available); noise stays seeded on the CPU."""
        self.device = resolve_device(device)
        self.net.to(self.device)
        return self

    def save_pretrained(self, path: str | Path, state: dict[str, torch.Tensor] | None = None) -> None:
        """Write the model folder (``state`` defaults to the network's current weights)."""
        state = state if state is not None else self.net.state_dict()
        extra = {"latent": to_dict(self.latent), "parent": self.parent}
        save_model_folder(path, MODEL_TYPE, to_dict(self.cfg), state, extra)

    @classmethod
    def from_pretrained(cls, path: str | Path) -> Transfer:
        path = resolve_model_folder(path)  # shipped:transfer: its parent is relative to the installed folder
        info, state = load_model_folder(path, MODEL_TYPE)
        where = f"{path / 'config.json'}"
        config = from_dict(TransferModelConfig, upgrade_saved_config(info["config"]), where)
        parent = str(info.get("parent", ""))
        if parent:  # shipped weights point at ../text2world, a recipe's run at its own (portable_reference)
            parent = str(resolve_reference(parent, path))
        model = cls(config, read_latent_info(info, path, config.dit), parent)
        load_weights(model.net, state, path)
        return model

    def conditioning(
        self, source: torch.Tensor, captions: list[str], targets: list[TargetCondition], fps: float | None = None
    ) -> TransferConditioning:
        """Conditioning of B samples: normalised source latents (B, c, t, h, w), a caption and a target each
        (on the CPU; ``.to(device)`` moves it)."""
        emb, mask = self.text_encoder.encode(captions)
        idx = torch.tensor([condition_indices(t.weather, t.time_of_day) for t in targets], dtype=torch.long)
        return TransferConditioning(
            emb.cpu(),
            mask.cpu(),
            torch.full((len(captions),), float(fps or self.latent.fps)),
            source=source,
            weather=idx[:, 0],
            time_of_day=idx[:, 1],
        )

    @torch.no_grad()
    def transfer_latents(
        self,
        source: torch.Tensor,
        captions: list[str],
        targets: list[TargetCondition],
        seeds: list[int],
        steps: int = 8,
        guidance: float = 1.0,
        sampler: str = "euler",
        start_sigma: float | None = None,
    ) -> torch.Tensor:
        """Raw latents (B, c, t, h, w) of raw ``source`` latents (B, c, t, h, w) in ``targets``.

        Sample b's noise comes from ``seeds[b]``. ``start_sigma`` None starts from pure noise at the
        schedule's sigma_max; a value starts from the source noised to it (SDEdit-style, fewer steps
        spent on the layout the source already gives).
        """
        mean, std = self._stats()
        z = normalize_latents(source.float(), mean, std, self.cfg.edm.sigma_data)
        cond = self.conditioning(z, captions, targets)
        start = z if start_sigma is not None else None
        x = sample(
            self.net,
            cond,
            z.shape[1:],
            seeds,
            steps,
            guidance,
            sampler,
            device=self.device,
            start=start,
            start_sigma=start_sigma,
        )
        return denormalize_latents(x, mean, std, self.cfg.edm.sigma_data)

    def _stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.tensor(self.latent.latent_mean), torch.tensor(self.latent.latent_std)
