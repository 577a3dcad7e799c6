"""Tokenizer benchmark: speed against the fastest peers at matched size, and quality at equal compute.

1. Throughput (``--throughput``, default on): encode and decode frames/s of drivewm's tokenizer and
   diffusers' video autoencoders built from configs of matched parameter count (randomly
   initialized: speed does not depend on the weights), same input, interleaved repeats, medians:
   - 8x8x8 against ``AutoencoderKLCosmos`` (the Cosmos tokenizer architecture: Haar patch 4,
     factorized causal convolutions, attention at the bottleneck) at two sizes;
   - 4x8x8 against ``AutoencoderKLCogVideoX``.
   Parameter counts and ours/peer ratios are printed beside every figure. On CUDA (when present)
   the same models run in bf16 autocast; on the CPU in fp32.
2. Quality at equal compute (``--data CLIPDIR``): drivewm's tiny tokenizer at 8x8x8 and the matched Cosmos
   architecture trained by the same loop (drivewm.train, the tokenizer task), loss, data and
   budget of CPU seconds (each model's step cost is measured first, interleaved, and its step
   count set to fill the budget), then scored on held-out simulated clips (PSNR, SSIM) and on the
   real dashcam video that neither saw.

    python benchmarks/bench_tokenizer.py                                   # throughput, ~2 min
    python benchmarks/bench_tokenizer.py --data CLIPDIR --budget-s 1800    # + equal-compute quality
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from drivewm.clips.video import decode_mp4
from drivewm.tokenizer import Tokenizer, preset
from drivewm.tokenizer.data import CameraVideos, load_clips, to_model_range
from drivewm.tokenizer.evaluate import video_metrics
from drivewm.tokenizer.latent_cache import clip_video
from drivewm.tokenizer.recipe import RECIPES
from drivewm.tokenizer.train import CropDataset, TokenizerTask
from drivewm.train.loop import train

REPO = Path(__file__).resolve().parents[1]
DASHCAM = REPO / ".." / "shared" / "data" / "video" / "dashcam_highway" / "solidWhiteRight.mp4"


def params_m(model: nn.Module) -> float:
    return sum(p.numel() for p in model.parameters()) / 1e6


class CosmosPeer(nn.Module):
    """diffusers' AutoencoderKLCosmos behind drivewm's tokenizer interface (deterministic latents:
    the posterior mode, as a drivewm tokenizer's latents are deterministic)."""

    def __init__(self, size: str):
        super().__init__()
        from diffusers import AutoencoderKLCosmos

        enc, dec = {"tiny": ((32, 64, 64, 64), (64, 64, 64, 64)), "small": ((32, 64, 128, 128), (64, 128, 128, 128))}[
            size
        ]
        self.net = AutoencoderKLCosmos(
            encoder_block_out_channels=enc, decode_block_out_channels=dec, num_layers=1, attention_resolutions=()
        )

    def encode(self, video: torch.Tensor) -> torch.Tensor:
        return self.net.encode(video).latent_dist.mode()

    def decode(self, latents: torch.Tensor) -> torch.Tensor:
        return self.net.decode(latents).sample

    def forward(self, video: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        latents = self.encode(video)
        return self.decode(latents), latents


def cogvideox_peer() -> nn.Module:
    """AutoencoderKLCogVideoX at 4x8x8 with 16 latent channels, as CogVideoX ships it but narrower."""
    from diffusers import AutoencoderKLCogVideoX

    class Peer(nn.Module):
        def __init__(self):
            super().__init__()
            self.net = AutoencoderKLCogVideoX(
                block_out_channels=(32, 64, 64, 128), layers_per_block=1, latent_channels=16
            )

        def encode(self, video):
            return self.net.encode(video).latent_dist.mode()

        def decode(self, latents):
            return self.net.decode(latents).sample

    return Peer()


def _seconds(fn) -> float:
    tic = time.perf_counter()
    fn()
    return time.perf_counter() - tic


def interleaved_medians(ours: nn.Module, other: nn.Module, video: torch.Tensor, repeats: int) -> dict[str, float]:
    """Median seconds of encode and decode of both models, runs interleaved (load drifts hit both alike)."""
    z = {"ours": ours.encode(video), "peer": other.encode(video)}  # also the warm-up
    models = {"ours": ours, "peer": other}
    runs: dict[str, list[float]] = {f"{who} {part}": [] for who in models for part in ("enc", "dec")}
    for _ in range(repeats):
        for who, model in models.items():
            runs[f"{who} enc"].append(_seconds(lambda m=model: m.encode(video)))
            runs[f"{who} dec"].append(_seconds(lambda m=model, w=who: m.decode(z[w])))
    return {k: statistics.median(v) for k, v in runs.items()}


@torch.no_grad()
def throughput(frames: int, height: int, width: int, repeats: int, device: torch.device) -> None:
    dtype = torch.bfloat16 if device.type == "cuda" else torch.float32
    threads = torch.get_num_threads()
    print(f"== throughput: 1 x 3 x {frames} x {height} x {width} on {device} ({dtype}), {threads} threads ==")
    video = (torch.rand(1, 3, frames, height, width, device=device) * 2 - 1).to(dtype)
    pairs = [
        (("tiny", "8x8x8"), CosmosPeer("tiny")),
        (("small", "8x8x8"), CosmosPeer("small")),
        (("small", "4x8x8"), cogvideox_peer()),
    ]
    for (size, compression), other in pairs:
        ours_name = f"{size} {compression}"
        torch.manual_seed(0)
        ours = Tokenizer(preset(size, compression)).eval().to(device, dtype)
        med = interleaved_medians(ours, other.eval().to(device, dtype), video, repeats)
        print(
            f"{ours_name}: drivewm {params_m(ours):.2f}M | {type(other.net).__name__} {params_m(other):.2f}M | "
            f"params ratio peer/ours {params_m(other) / params_m(ours):.2f}"
        )
        for part in ("enc", "dec"):
            ours_fps, peer_fps = frames / med[f"ours {part}"], frames / med[f"peer {part}"]
            print(
                f"  {part}ode frames/s: ours {ours_fps:8.1f}  peer {peer_fps:8.1f}  ratio {ours_fps / peer_fps:5.2f}x"
            )


class PeerTask(TokenizerTask):
    """The tokenizer task with the Cosmos architecture as the model: same loop, loss and data."""

    def __init__(self, cfg, dataset, size: str):
        super().__init__(cfg, dataset)
        torch.manual_seed(cfg.train.seed)
        self.model = CosmosPeer(size).train()

    def blocks(self) -> list[nn.Module]:
        return []

    def save_model(self, ema_state, out_dir: Path) -> None:
        torch.save(ema_state, out_dir / "peer_ema.pt")

    def sample_grid(self, ema_state, path: Path) -> None:
        pass


def dashcam_video(frames: int, stride: int, size_hw: tuple[int, int]) -> torch.Tensor:
    """The real dashcam clip: every ``stride``-th frame, area-resized, centre-cropped: (1, 3, T, H, W)."""
    raw = decode_mp4(DASHCAM.read_bytes(), None, str(DASHCAM))[: frames * stride : stride]
    video = to_model_range(raw).unsqueeze(0)  # (1, 3, T, 540, 960)
    h, w = size_hw
    scaled = F.interpolate(video[0].transpose(0, 1), size=(h, int(round(h * 960 / 540))), mode="area")
    left = (scaled.shape[-1] - w) // 2
    return scaled[..., left : left + w].transpose(0, 1).unsqueeze(0).clamp(-1, 1)


@torch.no_grad()
def score(model: nn.Module, video: torch.Tensor) -> dict[str, float]:
    """PSNR/SSIM of ``model`` on (N, 3, T, H, W), one video at a time."""
    recons = torch.cat([model.decode(model.encode(v[None])).clamp(-1, 1) for v in video])
    return video_metrics(recons, video)


def step_cpu_seconds(task: TokenizerTask, batch_size: int, repeats: int = 3) -> float:
    """Median thread CPU seconds of one training step (forward, backward, AdamW) of ``task.model``."""
    opt = torch.optim.AdamW(task.model.parameters(), lr=0.0)
    times = []
    for i in range(repeats + 1):
        tic = time.thread_time()
        loss, _ = task.loss(task.model, list(range(batch_size)), [i * batch_size + j for j in range(batch_size)], "cpu")
        loss.backward()
        opt.step()
        opt.zero_grad()
        times.append(time.thread_time() - tic)
    return statistics.median(times[1:])


def equal_compute(data: Path, budget_s: float, work: Path, holdout: int, max_heldout: int) -> None:
    overrides = ["train.batch_size=4", "data.frames=17", "data.crop=[64,96]", f"data.holdout_percent={holdout}"]
    overrides += ["train.lr=5e-4", "train.warmup_steps=50", "train.log_every=50", "train.ema_decay=0.99"]
    tiny = {"compression": "8x8x8"}
    base = RECIPES.resolve("tiny", None, overrides, tiny)
    videos = CameraVideos(load_clips(data, "train", holdout))
    dataset = CropDataset(videos, base.data.frames, tuple(base.data.crop))
    tasks = {"drivewm tiny 8x8x8": TokenizerTask(base, dataset), "Cosmos tiny": PeerTask(base, dataset, "tiny")}
    costs = {name: step_cpu_seconds(task, 4) for name, task in tasks.items()}
    heldout = torch.cat([clip_video(c) for c in load_clips(data, "holdout", holdout)])[:, :, :17]
    heldout = heldout[torch.linspace(0, len(heldout) - 1, min(max_heldout, len(heldout))).long()]  # spread evenly
    dashcam = dashcam_video(17, 2, (96, 160))
    print(f"== quality at equal compute: {budget_s:.0f} CPU-s each, same loop, loss, data ({len(heldout)} held-out) ==")
    for name, task in tasks.items():
        steps = max(1, int(budget_s / costs[name]))
        cfg = RECIPES.resolve(
            "tiny", None, [*overrides, f"train.steps={steps}", f"train.checkpoint_every={steps}"], tiny
        )
        task.cfg = cfg
        tic = time.thread_time()
        train(task, cfg.train, work / name.replace(" ", "_"))
        model = task.model.eval()
        sim, real = score(model, heldout), score(model, dashcam)
        print(
            f"{name:20s} {params_m(model):5.2f}M  {costs[name]:6.2f} CPU-s/step x {steps:5d} steps "
            f"({time.thread_time() - tic:.0f} CPU-s) | held-out sim PSNR {sim['psnr']:6.2f} SSIM {sim['ssim']:.3f} "
            f"| dashcam PSNR {real['psnr']:6.2f} SSIM {real['ssim']:.3f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, help="simulated clip folder for the equal-compute comparison")
    parser.add_argument("--budget-s", type=float, default=600.0, help="CPU seconds of training per model")
    parser.add_argument("--holdout-percent", type=int, default=25)
    parser.add_argument("--max-heldout", type=int, default=96, help="held-out camera videos scored, spread evenly")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--no-throughput", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if not args.no_throughput:
        throughput(17, 128, 224, args.repeats, device)
    if args.data:
        with tempfile.TemporaryDirectory() as work:
            equal_compute(args.data, args.budget_s, Path(work), args.holdout_percent, args.max_heldout)


if __name__ == "__main__":
    main()
