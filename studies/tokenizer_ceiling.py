"""What is the best a generator on this tokenizer could score? Real clips through the tokenizer.

A latent diffusion model can only emit what its tokenizer decodes. Encoding real held-out clips
and decoding them again gives clips with perfect latents: everything the benchmark then loses is
the tokenizer's, not the generator's. Scoring those clips with ``drivewm eval`` beside the raw
clips gives the ceiling of every figure of the worldmodel benchmark (pose success, TSE, CSE,
adherence) for any generator on this tokenizer, whatever its compute.

    python studies/tokenizer_ceiling.py CLIPDIR OUT [--tokenizer shipped:tokenizer] [--max-clips 48]
    drivewm eval OUT --rig nuscenes6 --out OUT_EVAL --reference REAL_EVAL/metrics.json --workers 2

Each coded clip keeps its source's metadata, ego poses and tags and is written with the same H.264
settings as ``drivewm generate``'s samples (crf 18), at the clips' own size (which must be one the
tokenizer takes: the shipped one is trained at 160x96). ``--max-clips`` spreads the subset over
the input as ``drivewm eval --max-clips`` does, so the same N clips are scored raw and coded.
Numbers: git show a88b7a4:docs/quality-vs-compute.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from tqdm import tqdm

from drivewm.clips import ShardWriter, iter_clips
from drivewm.clips.format import clip_from_arrays
from drivewm.clips.shards import spread
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.coding import code_views
from drivewm.tokenizer import Tokenizer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", help="a clip folder (shards), e.g. held-out simulated clips at 160x96")
    parser.add_argument("out", help="folder for the coded clips (shards + manifest)")
    parser.add_argument("--tokenizer", default="shipped:tokenizer")
    parser.add_argument("--max-clips", type=int, default=0, help="score N clips spread over the input (0: all)")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    tok = Tokenizer.from_pretrained(resolve_model_folder(args.tokenizer)).eval()
    clips = list(iter_clips(args.clips))
    clips = spread(clips, args.max_clips or None)  # the clips `drivewm eval --max-clips N` scores
    with ShardWriter(Path(args.out), "coded") as writer:
        for clip in tqdm(clips, desc="code clips"):
            frames = clip.videos()  # (V, T, H, W, 3) rig order
            coded = code_views(tok, frames, frames.shape[2:4])
            writer.write(clip_from_arrays(clip.meta, dict(zip(clip.meta.cameras, coded)), clip.T_world_from_ego))
    print(f"wrote {len(clips)} coded clips to {args.out}")


if __name__ == "__main__":
    main()
