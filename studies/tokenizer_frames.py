"""Which frames of a clip does a tokenizer code well? PSNR per latent frame on held-out clips.

A 17-frame clip is 5 latent frames at 4x8x8: frame 0 alone, then frames 1-4, 5-8, 9-12, 13-16. The
causal temporal convolutions see a different left context at each: replicated frame 0 before latent
frame 1, real frames from latent frame 2 on. A tokenizer trained on 5-frame crops (latent frames 0
and 1, the shipped tokenizer's first recipe) never learned latent frames 2-4, which make up
three quarters of every clip it codes; this study shows it and what training on the clip length buys.

    python studies/tokenizer_frames.py CLIPDIR LABEL=TOKENIZER ... [--every 4] [--plot FIGURE.png]

``--every N`` scores every N-th clip. Numbers: studies/README.md.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from tqdm import tqdm

from drivewm.tokenizer import Tokenizer
from drivewm.tokenizer.data import load_clips
from drivewm.tokenizer.evaluate import reconstruct
from drivewm.tokenizer.latent_cache import clip_video


def latent_frame_psnr(tok: Tokenizer, videos: list[torch.Tensor]) -> list[float]:
    """PSNR (dB, range [-1, 1]) of frame 0 and of each later group of ``temporal_compression`` frames."""
    f = tok.config.temporal_compression
    squared, count = None, 0
    for video in videos:  # (V, 3, T, H, W)
        recon, _ = reconstruct(tok, video)
        error = (recon - video[:, :, : recon.shape[2]]).pow(2).mean(dim=(0, 1, 3, 4)).double()  # (T,)
        squared, count = (error if squared is None else squared + error), count + 1
    per_frame = (squared / count).numpy()
    groups = [per_frame[:1]] + [per_frame[1 + k : 1 + k + f] for k in range(0, len(per_frame) - 1, f)]
    return [float(10 * np.log10(4 / g.mean())) for g in groups]


def plot(rows: dict[str, list[float]], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2))
    width = 0.8 / len(rows)
    for i, (label, values) in enumerate(rows.items()):
        ax.bar(np.arange(len(values)) + i * width, values, width, label=label)
    n = len(next(iter(rows.values())))
    ax.set_xticks(np.arange(n) + 0.4 - width / 2, ["frame 0"] + [f"latent frame {k}" for k in range(1, n)])
    ax.set_ylabel("held-out PSNR (dB)")
    ax.set_ylim(min(min(v) for v in rows.values()) - 2, max(max(v) for v in rows.values()) + 1)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", help="held-out clip folder (17-frame clips at the tokenizer's size)")
    parser.add_argument("tokenizers", nargs="+", help="LABEL=TOKENIZER_FOLDER (or shipped:tokenizer)")
    parser.add_argument("--every", type=int, default=4, help="score every N-th clip")
    parser.add_argument("--plot", help="write a bar chart here")
    args = parser.parse_args()
    clips = load_clips(args.clips)[:: args.every]
    videos = [clip_video(c) for c in tqdm(clips, desc="decode clips")]
    rows = {}
    for spec in args.tokenizers:
        label, _, path = spec.partition("=")
        rows[label] = latent_frame_psnr(Tokenizer.from_pretrained(path or label), videos)
        print(f"| {label} | " + " | ".join(f"{v:.2f}" for v in rows[label]) + " |", flush=True)
    if args.plot:
        plot(rows, args.plot)


if __name__ == "__main__":
    main()
