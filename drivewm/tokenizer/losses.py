"""The tokenizer's training loss: L1 + structural (1 - SSIM) + temporal (frame differences),
plus an optional perceptual term (VGG16 features, LPIPS-style, Zhang et al. 2018) that runs
only from weights the user has on disk: nothing is ever downloaded.
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from drivewm.errors import DrivewmError
from drivewm.tokenizer.config import LossConfig
from drivewm.tokenizer.metrics import ssim

# VGG16 ``features`` layout (torchvision key names): conv widths, "M" = max-pool.
_VGG16 = [64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512]
_VGG_TAPS = (3, 8, 15, 22)  # relu1_2, relu2_2, relu3_3, relu4_3 (indices in ``features``)


class VGGPerceptual(nn.Module):
    """Mean squared distance of unit-normalized VGG16 activations (LPIPS without learned weights)."""

    def __init__(self, weights_path: str | Path):
        super().__init__()
        layers: list[nn.Module] = []
        cin = 3
        for v in _VGG16:
            if v == "M":
                layers.append(nn.MaxPool2d(2))
            else:
                layers += [nn.Conv2d(cin, v, 3, padding=1), nn.ReLU()]
                cin = v
        self.features = nn.Sequential(*layers)
        self.features.load_state_dict(_load_vgg_state(Path(weights_path)))
        self.requires_grad_(False)
        self.register_buffer("mean", torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1))

    def forward(self, recon: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        a = rearrange(recon, "b c t h w -> (b t) c h w")
        b = rearrange(target, "b c t h w -> (b t) c h w")
        x = torch.cat([a, b]) * 0.5 + 0.5
        x = (x - self.mean) / self.std
        loss = x.new_zeros(())
        for i, layer in enumerate(self.features):
            x = layer(x)
            if i in _VGG_TAPS:
                fa, fb = F.normalize(x, dim=1).chunk(2)
                loss = loss + (fa - fb).pow(2).sum(1).mean()
            if i >= _VGG_TAPS[-1]:
                break
        return loss


def _load_vgg_state(path: Path) -> dict[str, torch.Tensor]:
    if not path.is_file():
        raise DrivewmError(f"{path}: perceptual weights not found (loss.perceptual_weights)")
    try:
        if path.suffix == ".safetensors":
            from safetensors.torch import load_file

            state = load_file(str(path))
        else:
            state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # many formats, many error types
        raise DrivewmError(f"{path}: cannot read VGG16 weights ({exc.__class__.__name__})") from None
    state = {k.removeprefix("features."): v for k, v in state.items() if k.startswith("features.") or k[0].isdigit()}
    wanted = {k for k in state if int(k.split(".")[0]) <= _VGG_TAPS[-1]}
    if not wanted:
        raise DrivewmError(f"{path}: no VGG16 'features.*' tensors found")
    return {k: state[k] for k in wanted}


class TokenizerLoss(nn.Module):
    """``loss(recon, target) -> (total, terms)`` for videos (B, 3, T, H, W) in [-1, 1]."""

    def __init__(self, cfg: LossConfig):
        super().__init__()
        cfg.validate()
        self.cfg = cfg
        self.perceptual = VGGPerceptual(cfg.perceptual_weights) if cfg.perceptual > 0 else None

    def forward(self, recon: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
        terms = {"l1": (recon - target).abs().mean(), "ssim": 1 - ssim(recon, target)}
        if target.shape[2] > 1:
            terms["temporal"] = (recon.diff(dim=2) - target.diff(dim=2)).abs().mean()
        if self.perceptual is not None:
            terms["perceptual"] = self.perceptual(recon, target)
        total = sum(getattr(self.cfg, k) * v for k, v in terms.items())
        return total, {k: v.item() for k, v in terms.items()}
