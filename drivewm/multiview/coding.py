"""Multi-view clips to and from the tokenizer: uint8 views (V, T, H, W, 3) <-> raw latents
(V, c, t, h, w), one view at a time (memory), at the tokenizer's input size."""

from __future__ import annotations

import cv2
import numpy as np
import torch
from einops import rearrange

from drivewm.diffusion.generate import video_to_uint8


def resize_views(frames: np.ndarray, size_hw: tuple[int, int], interpolation: int = cv2.INTER_AREA) -> np.ndarray:
    """uint8 (V, T, H, W, 3) -> uint8 (V, T, h, w, 3) at ``size_hw`` (the input itself when already that size)."""
    h, w = size_hw
    if frames.shape[2:4] == (h, w):
        return frames
    return np.stack([[cv2.resize(f, (w, h), interpolation=interpolation) for f in view] for view in frames])


def frames_to_video(frames: np.ndarray, size_hw: tuple[int, int]) -> torch.Tensor:
    """uint8 (V, T, H, W, 3) -> float (V, 3, T, h, w) in [-1, 1] at the tokenizer's input size."""
    frames = resize_views(frames, size_hw)
    return rearrange(torch.from_numpy(frames).float() / 127.5 - 1, "v t h w c -> v c t h w")


@torch.no_grad()
def encode_views(
    tokenizer, frames: np.ndarray, size_hw: tuple[int, int], device: torch.device | str = "cpu"
) -> torch.Tensor:
    """uint8 (V, T, H, W, 3) -> raw latents (V, c, t, h, w) on the CPU, coded on ``device`` (where the
    tokenizer is) one view at a time (memory)."""
    video = frames_to_video(frames, size_hw)
    return torch.cat([tokenizer.encode(v[None].to(device)).cpu() for v in video])


@torch.no_grad()
def decode_views(tokenizer, latents: torch.Tensor, device: torch.device | str = "cpu") -> np.ndarray:
    """Raw latents (V, c, t, h, w) -> uint8 (V, T, H, W, 3), decoded on ``device`` (where the tokenizer is)."""
    return np.concatenate([video_to_uint8(tokenizer.decode(z[None].to(device))) for z in latents])


def code_views(
    tokenizer, frames: np.ndarray, size_hw: tuple[int, int], device: torch.device | str = "cpu"
) -> np.ndarray:
    """uint8 (V, T, H, W, 3) resized to ``size_hw``, encoded and decoded: what the tokenizer keeps of them."""
    return decode_views(tokenizer, encode_views(tokenizer, frames, size_hw, device), device)
