"""Optional adversarial term: a per-frame PatchGAN discriminator (Isola et al. 2017, pix2pix) with
hinge losses (Lim & Ye 2017), trained alongside the tokenizer from ``loss.adversarial_start``.

It starts from scratch, or from a discriminator state dict the user has on disk
(``loss.discriminator_weights``, safetensors); nothing is downloaded.
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from drivewm.errors import DrivewmError


class PatchDiscriminator(nn.Module):
    """(B, 3, T, H, W) in [-1, 1] -> per-patch realness logits (B*T, 1, H/4, W/4), every frame alone."""

    def __init__(self, width: int = 32):
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(3, width, 4, 2, 1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(width, 2 * width, 4, 2, 1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(2 * width, 1, 3, 1, 1),
        )

    def forward(self, video: torch.Tensor) -> torch.Tensor:
        return self.net(rearrange(video, "b c t h w -> (b t) c h w"))


class Adversary:
    """The discriminator, its AdamW optimizer and the two hinge losses."""

    def __init__(self, lr: float, weights: str = ""):
        self.disc = PatchDiscriminator()
        if weights:
            self.disc.load_state_dict(_load(Path(weights)))
        self.opt = torch.optim.AdamW(self.disc.parameters(), lr=lr, betas=(0.5, 0.9))

    def to(self, device: torch.device) -> Adversary:
        """Move the discriminator and its optimizer state (loaded on the CPU when resuming)."""
        self.disc.to(device)
        for state in self.opt.state.values():
            for key, value in state.items():
                if isinstance(value, torch.Tensor) and key != "step":
                    state[key] = value.to(device)
        return self

    def generator_loss(self, recon: torch.Tensor) -> torch.Tensor:
        """-E[D(recon)]: the tokenizer is rewarded where the discriminator finds its output real."""
        return -self.disc(recon).mean()

    def discriminator_step(self, recon: torch.Tensor, real: torch.Tensor) -> float:
        """One hinge update: E[relu(1 - D(real))] + E[relu(1 + D(recon))]."""
        loss = F.relu(1 - self.disc(real)).mean() + F.relu(1 + self.disc(recon.detach())).mean()
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        self.opt.step()
        return loss.item()

    def state_dict(self) -> dict:
        return {"disc": self.disc.state_dict(), "opt": self.opt.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.disc.load_state_dict(state["disc"])
        self.opt.load_state_dict(state["opt"])


def _load(path: Path) -> dict[str, torch.Tensor]:
    from safetensors.torch import load_file

    if not path.is_file():
        raise DrivewmError(f"{path}: discriminator weights not found (loss.discriminator_weights)")
    try:
        return load_file(str(path))
    except Exception as exc:  # safetensors raises several types for bad files
        raise DrivewmError(f"{path}: cannot read discriminator weights ({exc.__class__.__name__})") from None
