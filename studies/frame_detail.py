"""How much road detail does each camera keep from a clip's first frame to its last?

SIFT needs texture: a camera pair's cross-view matches and a clip's frame-to-frame matches come
from the detail its frames hold. This prints, per camera, the mean absolute Laplacian of the lower
half of every frame (the road, in a rig whose cameras look level) at the first frame, over frames
1-4 (the first latent frame after it, at 4x temporal compression) and over the last four, for
clip folders (curated clips, ``drivewm generate`` output or anything ``drivewm eval`` reads);
``--coded TOKENIZER`` prints the same of the clips coded and decoded by that tokenizer (what any
generator on it could at best give back).

    python studies/frame_detail.py FOLDER [...] [--coded shipped:tokenizer] [--max-clips 48]

Numbers: git show a88b7a4:docs/quality-vs-compute.md, "Cameras that disagree where they overlap".
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from drivewm.eval.inputs import load_items
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.coding import code_views
from drivewm.tokenizer.model import Tokenizer


def road_detail(frames: np.ndarray) -> np.ndarray:
    """uint8 (T, H, W, 3) -> (T,) mean absolute Laplacian of each frame's lower half."""
    h = frames.shape[1]
    return np.array(
        [np.abs(cv2.Laplacian(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), cv2.CV_64F)[h // 2 :]).mean() for f in frames]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+")
    parser.add_argument("--coded", help="code and decode every clip with this tokenizer (folder or shipped:tokenizer)")
    parser.add_argument("--max-clips", type=int, default=48)
    args = parser.parse_args()
    tokenizer = Tokenizer.from_pretrained(resolve_model_folder(args.coded)).eval() if args.coded else None
    for folder in args.folders:
        items = load_items(folder)[: args.max_clips]
        rows: dict[str, list] = {}
        for item in items:
            videos = item.videos()
            names = list(videos)
            clips = np.stack([videos[n] for n in names])
            if tokenizer is not None:
                clips = code_views(tokenizer, clips, clips.shape[2:4])
            for name, frames in zip(names, clips):
                d = road_detail(frames)
                rows.setdefault(name, []).append((d[0], d[1:5].mean(), d[-4:].mean()))
        label = f"{folder} coded by {args.coded}" if tokenizer is not None else folder
        print(f"{label}: {len(items)} clips; road |Laplacian| at frame 0, frames 1-4, the last 4; last / first")
        for name, r in rows.items():
            first, early, last = np.mean(r, axis=0)
            print(f"  {name:18s} {first:6.2f} {early:6.2f} {last:6.2f}   {last / first:.2f}")


if __name__ == "__main__":
    main()
