"""Does the calibrated CSE of a real 1600x900 nuScenes keyframe depend on its H.264 quality?

The consistency benchmark verifies cross-view matches with thresholds in native pixels, so a
1600x900 rig should read one scene alike whatever the encoder kept of it. This takes the six
camera images of one nuScenes keyframe, encodes each as a one-frame H.264 mp4 (libx264 through
PyAV, the encoder ``drivewm`` writes its clips with) at every crf in a range, scores each encoding
with ``drivewm eval --rig nuscenes6_calib --metrics cse`` and prints, per camera pair, the
calibrated CSE at each crf and its spread: (max - min) / median over the crfs where the pair
counted. The keyframe used for docs/results.md is the one mmdetection3d ships for its demo
(open-mmlab/mmdetection3d, demo/data/nuscenes/: log n015-2018-07-24-11-22-45+0800, the log whose
calibration ``nuscenes6_calib`` carries; its demo pkl's cam2img equals the rig's K). nuScenes is
CC BY-NC-SA 4.0, so the images are not in this repository: give the folder holding them.

    python studies/nuscenes_keyframe_crf.py KEYFRAME_DIR --out RUN [--crf 12:23] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from drivewm.clips.video import encode_mp4
from drivewm.geometry import load_rig

RIG = "nuscenes6_calib"


def keyframe_images(folder: Path, cameras: list[str]) -> dict[str, np.ndarray]:
    """Each camera's RGB image: the one file in ``folder`` whose name holds ``__CAMERA__``."""
    images = {}
    for cam in cameras:
        found = sorted(folder.glob(f"*__{cam}__*.jpg"))
        if len(found) != 1:
            sys.exit(f"error: {folder}: want one *__{cam}__*.jpg, found {len(found)}")
        images[cam] = cv2.imread(str(found[0]), cv2.IMREAD_COLOR)[:, :, ::-1].copy()
    return images


def score(images: dict[str, np.ndarray], crf: int, run: Path, overrides: list[str]) -> dict:
    """The eval's per-clip entry for the keyframe encoded at ``crf``."""
    clip = run / f"crf{crf:02d}"
    clip.mkdir(parents=True, exist_ok=True)
    for cam, image in images.items():
        (clip / f"{cam}.mp4").write_bytes(encode_mp4(image[None], 12.0, crf=crf, preset="medium", threads=1))
    out = run / f"eval_crf{crf:02d}"
    cmd = ["drivewm", "eval", str(clip), "--rig", RIG, "--metrics", "cse", "--out", str(out), "--no-pictures"]
    cmd += [arg for item in overrides for arg in ("--set", item)]
    subprocess.run(cmd, check=True, capture_output=True)
    return json.loads((out / "metrics.json").read_text())["clips"][clip.name]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("keyframe", type=Path, help="folder with the six *__CAM_*__*.jpg of one keyframe")
    ap.add_argument("--out", type=Path, required=True, help="run folder for the mp4s and eval outputs")
    ap.add_argument("--crf", default="12:23", help="first:last crf (inclusive)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="an eval config override")
    args = ap.parse_args()
    first, last = (int(v) for v in args.crf.split(":"))
    images = keyframe_images(args.keyframe, [c.name for c in load_rig(RIG).cameras])

    per_crf = {crf: score(images, crf, args.out, args.set) for crf in range(first, last + 1)}
    pairs = next(iter(per_crf.values()))["cse_pairs"]
    print("calibrated CSE per camera pair (px at 320x192 scale; '-' the pair fell short of the match minimum)")
    print("pair".ljust(34) + "".join(f"crf{c:<5d}" for c in per_crf) + "spread")
    spreads = {}
    for i, pair in enumerate(pairs):
        values = [r["cse_calibrated_pair_medians"][i] for r in per_crf.values()]
        counted = [v for v in values if v is not None]
        cells = "".join(f"{v:<8.3f}" if v is not None else "-".ljust(8) for v in values)
        spread = (max(counted) - min(counted)) / float(np.median(counted)) if len(counted) == len(values) else None
        spreads[pair] = spread
        print(pair.ljust(34) + cells + (f"{spread:.1%}" if spread is not None else "not counted at every crf"))
    matches = {c: r["cse_calibrated_pair_matches"] for c, r in per_crf.items()}
    print("distinct verified matches per pair:", json.dumps(matches))
    scored = [s for s in spreads.values() if s is not None]
    print(f"pairs counted at every crf: {len(scored)} of {len(pairs)}; largest spread {max(scored):.1%} (goal 10%)")
    (args.out / "spread.json").write_text(json.dumps({"per_crf": per_crf, "spread": spreads}, indent=1))


if __name__ == "__main__":
    main()
