"""Does a generated clip keep moving as fast as a real one, frame pair after frame pair?

The pose figures need every frame to move the rig as the trajectory says; a clip whose motion
fades towards its end registers few frames and misses the trajectory's length even where its
epipolar geometry is right (TSE reads directions, not speeds). This prints, for clip folders
(curated clips, `drivewm generate` output or anything `drivewm eval` reads as shards), the median
dense-flow magnitude (OpenCV's Farneback) of every consecutive frame pair over the lower half of
each frame (the road), averaged over cameras and clips, with the ratio of the last four pairs to
the first four. With the 4x temporal tokenizer, pairs 0, 4, 8 and 12 cross a latent frame.

    python studies/motion_profile.py CLIPS_OR_SAMPLES [...] [--max-clips 6]

Dense flow reads low where texture is blurred (the far road a reprojection magnifies), so compare
folders at one resolution and read the ratio before the pixels.
Numbers: git show a88b7a4:docs/quality-vs-compute.md, "The 320x192 model continued on CPU".
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from drivewm.clips import iter_clips
from drivewm.clips.shards import spread


def pair_flow(frames: np.ndarray) -> np.ndarray:
    """uint8 (T, H, W, 3) -> (T - 1,) median Farneback flow magnitude (px) over the lower half."""
    gray = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in frames]
    out = []
    for a, b in zip(gray[:-1], gray[1:]):
        flow = cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 3, 15, 3, 5, 1.2, 0)
        out.append(float(np.median(np.linalg.norm(flow[a.shape[0] // 2 :], axis=-1))))
    return np.asarray(out)


def motion_profile(location: str, max_clips: int | None) -> np.ndarray:
    """(T - 1,) mean over cameras and clips (``max_clips`` spread over the folder) of :func:`pair_flow`."""
    clips = spread(list(iter_clips(location)), max_clips)
    return np.mean([[pair_flow(clip.video(c)) for c in clip.meta.cameras] for clip in clips], axis=(0, 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+")
    parser.add_argument("--max-clips", type=int, default=6, help="clips per folder, spread over it (0: all)")
    args = parser.parse_args()
    for folder in args.folders:
        p = motion_profile(folder, args.max_clips or None)
        ratio = p[-4:].mean() / p[:4].mean()
        print(f"{folder}: last 4 / first 4 pairs {ratio:.2f}; per pair (px) " + " ".join(f"{v:.2f}" for v in p))


if __name__ == "__main__":
    main()
