"""The AR model's held-out measurements: Video2World first-frame PSNR, rollout drift, codebook use.

    python studies/ar_measurements.py AR_DIR CLIPDIR [--clips 6] [--chunks 4] [--seed 0] [--top-k 50]

- Video2World: for each held-out clip (key-hash split, drivewm.tokenizer.data.is_holdout), every camera's
  first ``1 + f`` frames are given (two latent frames), the rest of the window is sampled under the clip's
  own ego poses; the first generated frame's PSNR against the true frame there is compared with the
  PSNR of a copy of the last given frame (the issue's bar: the model must be closer).
- Rollouts: from each held-out clip's first frame, ``--chunks`` windows (17 frames each at the default
  context) under a straight trajectory at the clip's speed; verified SIFT matches per frame pair
  (drivewm.eval.consistency.temporal_sampson, fitted F) of chunk 1 against chunk 4 (the bar: >= 80%).
- Codebook use of the FSQ tokenizer on the token cache (all clips): perplexity 2^H of the token
  frequencies, and dead codes (never used) out of the codebook.

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import torch

from drivewm.ar.generator import ARGenerator, clip_video
from drivewm.ar.sampling_config import TokenSampling
from drivewm.ar.tokens import TokenDataset
from drivewm.clips.latents import latent_cache_dir
from drivewm.eval.config import ConsistencyConfig, EpipolarConfig, MatchConfig
from drivewm.eval.consistency import temporal_sampson
from drivewm.eval.matching import FrameMatcher
from drivewm.multiview.trajectories import named_poses
from drivewm.tokenizer.data import load_clips
from drivewm.tokenizer.metrics import psnr


def to_uint8(video: torch.Tensor) -> np.ndarray:
    frames = ((video.clamp(-1, 1) + 1) * 127.5).round().byte().permute(0, 2, 3, 4, 1).numpy()  # (V, T, H, W, 3)
    return frames


def video2world_psnr(gen: ARGenerator, clip, sampling: TokenSampling, seed: int) -> dict:
    video = clip_video(clip)
    f = gen.frames_per_latent
    window = gen.window_video_frames()
    out = gen.video2world(
        video[:, :, : 1 + f], clip.meta.caption, clip.meta.get_rig(), clip.T_world_from_ego[:window], sampling, seed
    )
    true_next = video[:, :, 1 + f]
    return {"generated_db": psnr(out[:, :, 1 + f], true_next), "copy_last_db": psnr(video[:, :, f], true_next)}


def matches_per_pair(video: torch.Tensor, rig, poses: np.ndarray) -> float:
    frames = to_uint8(video)
    videos = {cam.name: frames[i] for i, cam in enumerate(rig.cameras)}
    result = temporal_sampson(videos, rig, poses, EpipolarConfig(), ConsistencyConfig(), FrameMatcher(MatchConfig()))
    return result["fitted"]["matches_per_pair"]


def rollout_drift(gen: ARGenerator, clip, chunks: int, sampling: TokenSampling, seed: int) -> list[float]:
    video = clip_video(clip)
    step = gen.window_video_frames() - 1
    T = clip.T_world_from_ego
    speed = float(np.linalg.norm(T[-1][:3, 3] - T[0][:3, 3])) / max(1e-6, (len(T) - 1) / clip.meta.fps)
    poses = named_poses("straight", 1 + chunks * step, 1 / clip.meta.fps, speed)
    windows = gen.rollout(video[:, :, :1], clip.meta.caption, clip.meta.get_rig(), poses, chunks, sampling, seed)
    return [
        matches_per_pair(w, clip.meta.get_rig(), poses[k * step : k * step + step + 1]) for k, w in enumerate(windows)
    ]


def codebook_use(cache_dir: Path) -> dict:
    data = TokenDataset(cache_dir)
    counts = torch.zeros(data.vocab_size, dtype=torch.float64)
    for i in range(len(data)):
        counts += torch.bincount(data[i].tokens.flatten(), minlength=data.vocab_size)
    p = counts[counts > 0] / counts.sum()
    entropy = float(-(p * torch.log2(p)).sum())
    return {
        "codebook": data.vocab_size,
        "perplexity": 2**entropy,
        "dead_codes": int((counts == 0).sum()),
        "tokens": int(counts.sum()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", type=Path)
    parser.add_argument("clips", type=Path)
    parser.add_argument("--clips-max", type=int, default=6)
    parser.add_argument("--chunks", type=int, default=4)
    parser.add_argument("--holdout-percent", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--top-k", type=int, default=50)
    parser.add_argument("--temperature", type=float, default=1.0)
    parser.add_argument("--skip-rollouts", action="store_true")
    args = parser.parse_args()
    torch.manual_seed(0)
    gen = ARGenerator(args.model)
    sampling = TokenSampling(temperature=args.temperature, top_k=args.top_k)
    clips = load_clips(args.clips, "holdout", args.holdout_percent)[: args.clips_max]
    v2w = [video2world_psnr(gen, c, sampling, args.seed + i) for i, c in enumerate(clips)]
    report = {
        "clips": [c.key for c in clips],
        "video2world": {k: float(np.mean([r[k] for r in v2w])) for k in v2w[0]},
        "video2world_per_clip": v2w,
        "video2world_closer": sum(r["generated_db"] > r["copy_last_db"] for r in v2w),
    }
    if not args.skip_rollouts:
        drift = [rollout_drift(gen, c, args.chunks, sampling, args.seed + i) for i, c in enumerate(clips)]
        per_chunk = [float(np.mean([d[k] for d in drift])) for k in range(args.chunks)]
        report["rollout_matches_per_chunk"] = per_chunk
        report["rollout_kept"] = per_chunk[-1] / per_chunk[0] if per_chunk[0] else math.nan
    tokenizer_dir = gen.tokenizer_dir
    report["codebook"] = codebook_use(latent_cache_dir(args.clips, None, tokenizer_dir))
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
