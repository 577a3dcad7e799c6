"""Tokenizer benchmark: speed against diffusers peers, reconstruction on simulated and real video.

1. Throughput: encode and decode frames/s of drivewm's tokenizer and a diffusers video
   autoencoder of similar size and the same compression, randomly initialized from a config
   (speed does not depend on the weights), same input, same process: 4x8x8 against
   AutoencoderKLCogVideoX, 8x8x8 against AutoencoderKLLTXVideo. Prints ours/peer ratios.
2. Reconstruction: debug-4x8x8 and debug-8x8x8 trained ``--steps`` steps on simulated clips,
   scored on held-out simulated clips and on the real dashcam video (never trained on: a
   generalization check), next to the block-mean codec (8x8 mean per frame, bilinear
   upsampling) measured on the same frames; prints PSNR/SSIM, their difference to it, and the
   compression rate.

    python benchmarks/bench_tokenizer.py --data CLIPDIR            # small, CPU, a few minutes
    python benchmarks/bench_tokenizer.py --data CLIPDIR --full     # bigger input, more steps
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
import torch.nn.functional as F

from drivewm.clips.video import decode_mp4
from drivewm.tokenizer import Tokenizer, preset
from drivewm.tokenizer.data import load_clips, to_model_range
from drivewm.tokenizer.evaluate import reconstruct, video_metrics
from drivewm.tokenizer.latent_cache import clip_video
from drivewm.tokenizer.train import TokenizerTrainConfig, train

REPO = Path(__file__).resolve().parents[1]
DASHCAM = REPO / ".." / "shared" / "data" / "video" / "dashcam_highway" / "solidWhiteRight.mp4"


def params_m(model: torch.nn.Module) -> float:
    return sum(p.numel() for p in model.parameters()) / 1e6


def timed(fn, repeats: int) -> tuple[float, object]:
    out = fn()  # warm-up
    t0 = time.perf_counter()
    for _ in range(repeats):
        out = fn()
    return (time.perf_counter() - t0) / repeats, out


def peer(kind: str) -> torch.nn.Module:
    from diffusers import AutoencoderKLCogVideoX, AutoencoderKLLTXVideo

    if kind == "cogvideox":  # 4x8x8, 16 channels
        return AutoencoderKLCogVideoX(block_out_channels=(32, 64, 64, 128), layers_per_block=2, latent_channels=16)
    boc = (32, 64, 128, 128)  # LTX-Video with patch size 1 and three 2x2x2 stages: 8x8x8, 16 channels
    return AutoencoderKLLTXVideo(
        latent_channels=16,
        block_out_channels=boc,
        decoder_block_out_channels=boc,
        layers_per_block=(1, 1, 1, 1, 1),
        decoder_layers_per_block=(1, 1, 1, 1, 1),
        patch_size=1,
        patch_size_t=1,
    )


@torch.no_grad()
def throughput(frames: int, height: int, width: int, repeats: int) -> None:
    print(f"== throughput: 1 x 3 x {frames} x {height} x {width}, {torch.get_num_threads()} threads, fp32 CPU ==")
    video = torch.rand(1, 3, frames, height, width) * 2 - 1
    for ours_name, peer_name in (("small-4x8x8", "cogvideox"), ("small-8x8x8", "ltx")):
        torch.manual_seed(0)
        ours, other = Tokenizer(preset(ours_name)).eval(), peer(peer_name).eval()
        t_enc, z = timed(lambda ours=ours: ours.encode(video), repeats)
        t_dec, _ = timed(lambda ours=ours, z=z: ours.decode(z), repeats)
        p_enc, pz = timed(lambda other=other: other.encode(video).latent_dist.mode(), repeats)
        p_dec, _ = timed(lambda other=other, pz=pz: other.decode(pz).sample, repeats)
        print(
            f"{ours_name} ({params_m(ours):.1f}M, latents {tuple(z.shape)}) vs {peer_name} ({params_m(other):.1f}M, "
            f"latents {tuple(pz.shape)})"
        )
        print(f"  encode frames/s: ours {frames / t_enc:7.2f}  peer {frames / p_enc:7.2f}  ratio {p_enc / t_enc:5.2f}x")
        print(f"  decode frames/s: ours {frames / t_dec:7.2f}  peer {frames / p_dec:7.2f}  ratio {p_dec / t_dec:5.2f}x")


def block_mean_codec(video: torch.Tensor) -> torch.Tensor:
    """(B, 3, T, H, W): 8x8 mean per frame, bilinear back up (3 values per 8x8 block of every frame)."""
    b, _, t, h, w = video.shape
    frames = video.transpose(1, 2).flatten(0, 1)
    up = F.interpolate(F.avg_pool2d(frames, 8), size=(h, w), mode="bilinear", align_corners=False)
    return up.view(b, t, 3, h, w).transpose(1, 2)


def dashcam_video(frames: int, stride: int, size_hw: tuple[int, int]) -> torch.Tensor:
    """The real dashcam clip: every ``stride``-th frame (25 fps -> 12.5), resized to ``size_hw``: (1, 3, T, H, W)."""
    raw = decode_mp4(DASHCAM.read_bytes(), None, str(DASHCAM))[: frames * stride : stride]
    video = to_model_range(raw).unsqueeze(0)  # (1, 3, T, 540, 960)
    h, w = size_hw
    scaled = F.interpolate(
        video.transpose(1, 2).flatten(0, 1), size=(h * 2, int(round(h * 2 * 960 / 540))), mode="area"
    )
    top, left = (scaled.shape[-2] - h) // 2, (scaled.shape[-1] - w) // 2
    return scaled[..., top : top + h, left : left + w].unsqueeze(0).transpose(1, 2).clamp(-1, 1)


def score(name: str, tok: Tokenizer, video: torch.Tensor) -> None:
    recon, latents = reconstruct(tok, video)
    ours = video_metrics(recon, video)
    base = video_metrics(block_mean_codec(video[:, :, : recon.shape[2]]), video)
    ratio = video[0, :, : recon.shape[2]].numel() / latents[0].numel()
    print(
        f"  {name:22s} PSNR {ours['psnr']:6.2f} dB  SSIM {ours['ssim']:.3f}  temporal_l1 {ours['temporal_l1']:5.2f}  | "
        f"block-mean codec PSNR {base['psnr']:6.2f} SSIM {base['ssim']:.3f}  (ours - it: "
        f"{ours['psnr'] - base['psnr']:+.2f} dB)"
        f"  | compression {ratio:.1f}x"
    )


def reconstruction(data: Path, steps: int, crop: list[int], work: Path, holdout: int) -> None:
    print(f"== reconstruction: debug presets trained {steps} steps on {data} (held out: {holdout}% of clips by key) ==")
    heldout = torch.cat([clip_video(c) for c in load_clips(data, "holdout", holdout)])  # (N*V, 3, T, H, W)
    dashcam = dashcam_video(33, 2, (176, 320))
    for name, frames in (("debug-4x8x8", 9), ("debug-8x8x8", 17)):
        cfg = TokenizerTrainConfig(model=preset(name), steps=steps, frames=frames, crop=crop, holdout_percent=holdout)
        t0 = time.perf_counter()
        train(data, work / name, cfg, progress=False)
        print(f"{name}: trained in {time.perf_counter() - t0:.0f} s")
        tok = Tokenizer.from_pretrained(work / name)
        score("held-out simulated", tok, heldout)
        score("real dashcam (unseen)", tok, dashcam)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--data", type=Path, help="simulated clip folder (e.g. curated sim drives); omit to skip part 2"
    )
    parser.add_argument("--full", action="store_true", help="bigger input and longer training")
    parser.add_argument("--steps", type=int, default=None, help="training steps per preset (default 150, --full 2000)")
    parser.add_argument("--holdout-percent", type=int, default=25)
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--skip-throughput", action="store_true")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if not args.skip_throughput:
        throughput(*((33, 256, 448, 2) if args.full else (17, 128, 224, 1)))
    if args.data:
        steps = args.steps or (2000 if args.full else 150)
        with tempfile.TemporaryDirectory() as work:
            reconstruction(args.data, steps, [128, 192] if args.full else [64, 96], Path(work), args.holdout_percent)


if __name__ == "__main__":
    main()
