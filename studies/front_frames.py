"""The front camera of benchmark samples side by side: one row per (prompt, run), frames across.

Benchmark runs of ``drivewm worldmodel benchmark`` share prompts and seeds, so the same row of two
runs is the same first pass under two sampling settings (e.g. two ``--reproject`` SIGMAs). Each row
is the first sample's CAM_FRONT at the given frames, labelled with the run and the prompt's name.

    python studies/front_frames.py --run "sigma 0.5=RUN_A" --run "sigma 0.3=RUN_B" \\
        --prompts snow_left,night_left,clear_right --out docs/figures/reproject_sigma.jpg

Numbers: git show a88b7a4:docs/quality-vs-compute.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from quality_vs_compute import stack_images

from drivewm.clips.shards import iter_clips

LABEL_PX = 14


def front_row(generated: Path, frames: list[int], camera: str = "CAM_FRONT") -> np.ndarray:
    """uint8 (H, W * len(frames), 3): the first clip's ``camera`` at ``frames``, left to right."""
    clip = next(iter_clips(generated))
    video = clip.video(camera)
    return np.concatenate([video[min(f, len(video) - 1)] for f in frames], axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", action="append", required=True, help="LABEL=RUN (a benchmark run folder)")
    parser.add_argument("--prompts", required=True, help="comma-separated benchmark names (RUN/generated/NAME)")
    parser.add_argument("--frames", default="0,4,8,12,16")
    parser.add_argument("--out", type=Path, required=True, help="image to write (.jpg)")
    args = parser.parse_args()
    runs = [tuple(r.split("=", 1)) for r in args.run]
    frames = [int(f) for f in args.frames.split(",")]
    rows = []
    for name in args.prompts.split(","):
        for label, run in runs:
            strip = Image.fromarray(front_row(Path(run) / "generated" / name, frames))
            canvas = Image.new("RGB", (strip.width, strip.height + LABEL_PX), "white")
            canvas.paste(strip, (0, LABEL_PX))
            ImageDraw.Draw(canvas).text((2, 1), f"{name}, {label}", fill="black")
            rows.append(canvas)
    stack_images(rows, args.out)


if __name__ == "__main__":
    main()
