"""Encode and decode videos longer or larger than fit in memory.

Time: the video is coded in chunks of latent frames, each through the same
:class:`CausalContext`, so every causal layer continues from the frames it saw; the result
equals one pass up to float rounding. Space: the frame is cut into overlapping tiles, each
coded alone (with its own causal context), and the overlaps are blended with linear ramps
(continuous latents and pixels) or stitched at the overlap's middle (FSQ codes, which must stay
on the code grid). Tiles differ from one pass only where a layer's receptive field crosses a
tile border, which the overlap keeps to the blended margin.
"""

from __future__ import annotations

import dataclasses

import torch

from drivewm.config import at_least
from drivewm.errors import DrivewmError
from drivewm.tokenizer.causal import CausalContext
from drivewm.tokenizer.model import Tokenizer


@dataclasses.dataclass
class TilingConfig:
    """How to cut a video for :func:`encode_tiled` / :func:`decode_tiled`."""

    chunk_latent_frames: int | None = 4
    """Latent frames per temporal chunk (the first chunk's covers 1 + (n-1)*f frames); None: one chunk."""
    tile_latent: int | None = 24
    """Tile height and width in latent pixels; None: no spatial tiling."""
    overlap_latent: int = 6
    """Overlap between neighbouring tiles in latent pixels (at least the decoder's receptive radius)."""

    def validate(self) -> None:
        if self.chunk_latent_frames is not None and self.chunk_latent_frames < 1:
            raise DrivewmError(f"tiling: chunk_latent_frames must be >= 1, got {self.chunk_latent_frames}")
        at_least(self, 0, "overlap_latent")
        if self.tile_latent is not None and not 0 <= self.overlap_latent < self.tile_latent:
            raise DrivewmError(
                f"tiling: need 0 <= overlap_latent < tile_latent, got {self.overlap_latent}, {self.tile_latent}"
            )


def tile_starts(size: int, tile: int, overlap: int) -> list[int]:
    """Start offsets of tiles of length ``tile`` covering [0, size) with at least ``overlap`` shared."""
    if size <= tile:
        return [0]
    starts = list(range(0, size - tile, tile - overlap))
    return starts + [size - tile]


def ramp(length: int, ramp_len: int, left: bool, right: bool, hard: bool) -> torch.Tensor:
    """1D blend weight of one tile: rising over ``ramp_len`` at sides that have a neighbour."""
    i = torch.arange(length, dtype=torch.float32)
    w = torch.ones(length)
    if hard:  # stitch at the overlap middle: each position owned by exactly one tile
        half = ramp_len // 2
        if left:
            w = torch.where(i < half, torch.zeros_like(w), w)
        if right:
            w = torch.where(i >= length - (ramp_len - half), torch.zeros_like(w), w)
        return w
    if left:
        w = torch.minimum(w, (i + 1) / (ramp_len + 1))
    if right:
        w = torch.minimum(w, (length - i) / (ramp_len + 1))
    return w


def _chunk_bounds(total: int, first_len: int | None, chunk_len: int | None) -> list[tuple[int, int]]:
    """[start, end) ranges along time: one of ``first_len``, then ``chunk_len`` each (the last may be shorter)."""
    if first_len is None or total <= first_len:
        return [(0, total)]
    bounds = [(0, first_len)]
    while bounds[-1][1] < total:
        start = bounds[-1][1]
        bounds.append((start, min(start + chunk_len, total)))
    return bounds


def _run_chunks(fn, x: torch.Tensor, bounds: list[tuple[int, int]]) -> torch.Tensor:
    """Apply ``fn(chunk, ctx)`` along dim 2 chunk by chunk with one causal context."""
    ctx = CausalContext()
    outs = []
    for start, end in bounds:
        outs.append(fn(x[:, :, start:end], ctx))
        ctx.next_chunk()
    return torch.cat(outs, dim=2)


def _blend_tiles(fn, x: torch.Tensor, tile: int, overlap: int, scale: float, hard: bool) -> torch.Tensor:
    """Run ``fn`` on overlapping spatial tiles of ``x`` (B, C, T, H, W) and blend the outputs,
    whose spatial size is ``scale`` times the input's."""
    height, width = x.shape[-2:]
    ys, xs = tile_starts(height, tile, overlap), tile_starts(width, tile, overlap)
    out = weight = None
    for y0 in ys:
        for x0 in xs:
            part = fn(x[..., y0 : y0 + tile, x0 : x0 + tile])  # (B, C', T', th*scale, tw*scale)
            th, tw = part.shape[-2:]
            wy = ramp(th, int(overlap * scale), y0 > 0, y0 + tile < height, hard)
            wx = ramp(tw, int(overlap * scale), x0 > 0, x0 + tile < width, hard)
            w = (wy[:, None] * wx[None, :]).to(part)
            if out is None:
                out = part.new_zeros(*part.shape[:-2], int(height * scale), int(width * scale))
                weight = part.new_zeros(int(height * scale), int(width * scale))
            oy, ox = int(y0 * scale), int(x0 * scale)
            out[..., oy : oy + th, ox : ox + tw] += part * w
            weight[oy : oy + th, ox : ox + tw] += w
    return out / weight


@torch.no_grad()
def encode_tiled(tok: Tokenizer, video: torch.Tensor, tiling: TilingConfig | None = None) -> torch.Tensor:
    """:meth:`Tokenizer.encode` of (B, 3, T, H, W) in [-1, 1] in causal time chunks and spatial tiles."""
    tiling = tiling or TilingConfig()
    tiling.validate()
    tok.check_video(video)
    f, s = tok.config.temporal_compression, tok.config.spatial_compression
    n = tiling.chunk_latent_frames
    bounds = _chunk_bounds(video.shape[2], None if n is None else 1 + (n - 1) * f, None if n is None else n * f)

    def encode_tile(tile_video: torch.Tensor) -> torch.Tensor:
        return _run_chunks(tok.encode, tile_video, bounds)

    if tiling.tile_latent is None:
        return encode_tile(video)
    hard = tok.quantizer is not None
    return _blend_tiles(encode_tile, video, tiling.tile_latent * s, tiling.overlap_latent * s, 1.0 / s, hard)


@torch.no_grad()
def decode_tiled(tok: Tokenizer, latents: torch.Tensor, tiling: TilingConfig | None = None) -> torch.Tensor:
    """:meth:`Tokenizer.decode` of (B, c, t, h, w) in causal time chunks and blended spatial tiles."""
    tiling = tiling or TilingConfig()
    tiling.validate()
    tok.check_latents(latents)
    bounds = _chunk_bounds(latents.shape[2], tiling.chunk_latent_frames, tiling.chunk_latent_frames)

    def decode_tile(tile_latents: torch.Tensor) -> torch.Tensor:
        return _run_chunks(tok.decode, tile_latents, bounds)

    if tiling.tile_latent is None:
        return decode_tile(latents)
    s = tok.config.spatial_compression
    return _blend_tiles(decode_tile, latents, tiling.tile_latent, tiling.overlap_latent, float(s), hard=False)
