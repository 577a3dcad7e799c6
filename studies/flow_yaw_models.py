"""How well does the eval's dense-flow reader get a clip's turn, per motion model?

The worldmodel benchmark's turn sign reads the yaw of generated clips from dense optical flow of the
front camera (structure from motion registers none of them). This scores that reader on clips
whose turn is known, the logged heading change of real simulated clips, raw or coded by a
tokenizer (``studies/tokenizer_ceiling.py``), for each ``FlowMotionConfig.motion_model``:

    python studies/flow_yaw_models.py CLIPDIR [CLIPDIR ...] [--camera CAM_FRONT] [--min-turn-deg 10]

Per folder and model: the share of clips turning at least ``--min-turn-deg`` whose reading has the
logged sign, the median absolute yaw error over all clips, the mean absolute reading of straight
clips (logged turn under 3 degrees) and the seconds per clip. Numbers: docs/eval-protocol.md (Yaw).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from tqdm import tqdm

from drivewm.clips import iter_clips
from drivewm.eval.flow_motion import MOTION_MODELS, FlowMotionConfig, flow_ego_trajectory
from drivewm.eval.trajectory_errors import heading_change_deg


def readings(folder: str, camera: str) -> list[dict[str, float]]:
    """Per clip: the logged heading change and each motion model's reading (deg) and seconds."""
    rows = []
    for clip in tqdm(list(iter_clips(folder)), desc=folder):
        cam = clip.meta.get_rig().camera(camera)
        row = {"logged": heading_change_deg(clip.T_world_from_ego)}
        for model in MOTION_MODELS:
            tic = time.perf_counter()
            ego = flow_ego_trajectory(clip.video(camera), cam, FlowMotionConfig(motion_model=model))
            reg = ego.T_world_from_ego[ego.registered]
            row[model] = heading_change_deg(reg) if len(reg) >= 2 else math.nan
            row[f"{model}_s"] = time.perf_counter() - tic
        rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", help="clip folders with logged ego poses (raw or coded)")
    parser.add_argument("--camera", default="CAM_FRONT")
    parser.add_argument("--min-turn-deg", type=float, default=10.0)
    args = parser.parse_args()
    for folder in args.folders:
        rows = readings(folder, args.camera)
        turning = [r for r in rows if abs(r["logged"]) >= args.min_turn_deg]
        straight = [r for r in rows if abs(r["logged"]) < 3.0]
        for model in MOTION_MODELS:
            sign = sum(np.sign(r[model]) == np.sign(r["logged"]) for r in turning)
            error = np.nanmedian([abs(r[model] - r["logged"]) for r in rows])
            spurious = np.nanmean([abs(r[model]) for r in straight]) if straight else math.nan
            seconds = np.mean([r[f"{model}_s"] for r in rows])
            print(
                f"{folder}: {model}: sign {sign} / {len(turning)} turning >= {args.min_turn_deg:g} deg; "
                f"median |error| {error:.2f} deg; straight clips' mean |yaw| {spurious:.2f} deg; "
                f"{seconds:.2f} s per clip"
            )


if __name__ == "__main__":
    main()
