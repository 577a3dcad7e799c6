"""Does the sampling noise steer a multi-view model's samples (``multiview.warped_noise``)?

A model trained on noise warped along each clip's own trajectory (drivewm.multiview.warped_noise)
should carry the motion of its noise into its samples, as Go-with-the-Flow's models do. This holds
the prompt, the seed and the conditioned trajectory fixed and warps the noise along a left turn and
along a right turn: if the noise steers, the front camera's content moves right under the left-turn
noise (a left turn) and left under the right-turn noise. It reads the front camera's median
horizontal optical flow (OpenCV Farneback) summed over the clip's frame pairs, in pixels of the
decoded 160x96 video; a 36 degree turn over the clip moves the front camera's content by about 70
(fx 115 px x 0.62 rad).

    python studies/noise_steering.py MODEL_DIR [--trajectory straight] [--strength A] [--prompts 4]

``--strength``: sample with this correlation instead of the model's own (e.g. 0.9 on a model trained
on independent noise: does noise alone steer it?). Prints one row per prompt: the flow under each
noise and their difference (left minus right: positive where the noise steers). About 30 s per
sample on 2 CPU cores. Numbers: git show a88b7a4:docs/quality-vs-compute.md, "Warped noise".
"""

from __future__ import annotations

import argparse
import dataclasses

import cv2
import numpy as np

from drivewm.diffusion.generate import decode_latents
from drivewm.geometry import load_rig
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.generate import view_captions
from drivewm.multiview.model import MultiView
from drivewm.multiview.trajectories import resolve_trajectory

PROMPTS = [
    "a clear day on a suburban road",
    "grey overcast sky over an urban grid",
    "a snowy road through fields",
    "rain on a wet multi-lane road",
    "thick fog over a divided highway",
    "a dark night drive past lit houses",
]


def flow_x(video: np.ndarray) -> float:
    """Median horizontal Farneback flow (px) of consecutive frames (T, H, W, 3) uint8, summed."""
    grey = [cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY) for f in video]
    flows = [cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 3, 15, 3, 5, 1.2, 0) for a, b in zip(grey, grey[1:])]
    return float(sum(np.median(f[..., 0]) for f in flows))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="a multi-view model folder, or shipped:multiview")
    parser.add_argument("--trajectory", default="straight", help="the trajectory the model is conditioned on")
    parser.add_argument("--strength", type=float, default=None, help="noise correlation (default the model's)")
    parser.add_argument("--prompts", type=int, default=4, help=f"how many of the {len(PROMPTS)} prompts")
    parser.add_argument("--seed", type=int, default=500)
    args = parser.parse_args()

    model = MultiView.from_pretrained(resolve_model_folder(args.model))
    mv = model.cfg.multiview
    if args.strength is not None:
        model.cfg = dataclasses.replace(model.cfg, multiview=dataclasses.replace(mv, warped_noise=args.strength))
    if not model.cfg.multiview.warped_noise:
        parser.error(f"{args.model} samples independent noise: give --strength")
    rig = load_rig("nuscenes6")
    named = {n: resolve_trajectory(n, mv.trajectory_waypoints, mv.trajectory_dt_s, mv.speed_mps)[None]
             for n in ("left", "right", args.trajectory)}  # fmt: skip
    warper = model.noise_warper
    diffs = []
    for i, prompt in enumerate(PROMPTS[: args.prompts]):
        flows = []
        for turn in ("left", "right"):
            model.noise_warper = lambda rig_, _traj, fps, turn=turn: warper(rig_, named[turn], fps)
            caps = [view_captions(prompt, rig)]
            z = model.sample_latents(rig, caps, named[args.trajectory], [args.seed + i], 20, 7.0)
            flows.append(flow_x(decode_latents(z[0], model.latent.tokenizer, model.device)[0]))
        diffs.append(flows[0] - flows[1])
        print(f"{prompt:40s} left-turn noise {flows[0]:+6.1f}  right-turn noise {flows[1]:+6.1f}  "
              f"difference {diffs[-1]:+6.1f} px", flush=True)  # fmt: skip
    positive = sum(d > 0 for d in diffs)
    print(f"mean difference {np.mean(diffs):+.1f} px over {len(diffs)} prompts; positive in {positive}")


if __name__ == "__main__":
    main()
