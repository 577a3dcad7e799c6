"""How good is the best *linear* code of the tokenizer's blocks, per weather and time of day?

The tokenizer codes each block of 4 frames x 8 x 8 pixels x 3 colours (768 values) into 16
numbers. Principal components (Karhunen-Loeve) are the best linear code of that size in squared
error, so their PSNR is the reference a trained network has to beat before it earns its FLOPs. The
clips' drives are split in two by sorted name (every other drive): the components are fitted on
blocks of the first half and scored on every clip of the second, next to a tokenizer's per-clip
PSNR from ``drivewm tokenizer eval``'s metrics.json when given.

    python studies/linear_code_reference.py CLIPDIR [--channels 16,32] [--tokenizer-metrics EVAL/metrics.json ...]

Blocks start at frame 1 (frame 0 is coded alone by the tokenizer and scores higher), so the
reference is slightly harsh on itself. Numbers: studies/README.md.
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np
from tqdm import tqdm

from drivewm.tokenizer.data import load_clips
from drivewm.tokenizer.latent_cache import clip_video

BLOCKS_PER_CLIP = 800  # blocks sampled from each fitting clip (6 cameras x 2 x 12 x 20 = 2,880 in a 160x96 clip)


def pixel_blocks(video: np.ndarray, frames: int = 4, size: int = 8) -> np.ndarray:
    """(V, 3, T, H, W) in 8-bit levels -> (N, 3 * frames * size^2) blocks after frame 0."""
    v, c, t, h, w = video.shape
    usable = (t - 1) // frames * frames
    x = video[:, :, 1 : 1 + usable].reshape(v, c, usable // frames, frames, h // size, size, w // size, size)
    return x.transpose(0, 2, 4, 6, 1, 3, 5, 7).reshape(-1, c * frames * size * size)


def condition(key: str) -> str:
    """``highway_merge_fog_day_s5050-000003`` -> ``highway_merge_fog_day`` (the drive without its seed)."""
    return key.split("-")[0].rsplit("_", 1)[0]


def psnr_db(coded: np.ndarray, blocks: np.ndarray) -> float:
    return float(10 * np.log10(255**2 / np.mean((np.clip(coded, 0, 255) - blocks) ** 2)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", help="clip folder with several drives (e.g. held-out simulated clips at 160x96)")
    parser.add_argument("--channels", default="16,32", help="code sizes to score (comma-separated)")
    parser.add_argument("--tokenizer-metrics", nargs="*", default=[], help="metrics.json of `drivewm tokenizer eval`")
    args = parser.parse_args()
    channels = [int(c) for c in args.channels.split(",")]
    clips = load_clips(args.clips)
    drives = sorted({c.key.split("-")[0] for c in clips})
    fitting = set(drives[0::2])
    rng = np.random.default_rng(0)
    fit = []
    for clip in tqdm([c for c in clips if c.key.split("-")[0] in fitting], desc="fit"):
        blocks = pixel_blocks((clip_video(clip).numpy() + 1) * 127.5)
        fit.append(blocks[rng.choice(len(blocks), min(BLOCKS_PER_CLIP, len(blocks)), replace=False)])
    fit = np.concatenate(fit).astype(np.float64)
    mean = fit.mean(0)
    _, _, components = np.linalg.svd(fit - mean, full_matrices=False)  # rows: principal directions
    tokenizers = [json.load(open(path))["clips"] for path in args.tokenizer_metrics]
    rows = collections.defaultdict(list)
    for clip in tqdm([c for c in clips if c.key.split("-")[0] not in fitting], desc="score"):
        blocks = pixel_blocks((clip_video(clip).numpy() + 1) * 127.5)
        row = [psnr_db((blocks - mean) @ components[:k].T @ components[:k] + mean, blocks) for k in channels]
        rows[condition(clip.key)].append(row + [t[clip.key]["psnr"] for t in tokenizers])
    header = [f"PCA-{k}" for k in channels] + [f"tokenizer {i + 1}" for i in range(len(tokenizers))]
    print(f"fitted on {len(fitting)} drives ({len(fit)} blocks), scored on {sum(map(len, rows.values()))} clips")
    print("| drive | clips | " + " | ".join(header) + " |")
    print("|---" * (len(header) + 2) + "|")
    for name, values in sorted(rows.items()):
        print(f"| {name} | {len(values)} | " + " | ".join(f"{v:.2f}" for v in np.mean(values, 0)) + " |")
    everything = np.concatenate([np.array(v) for v in rows.values()])
    print("| **all** | " + f"{len(everything)} | " + " | ".join(f"**{v:.2f}**" for v in everything.mean(0)) + " |")


if __name__ == "__main__":
    main()
