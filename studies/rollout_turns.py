"""Does a multi-view model turn the way it is told when it continues a real clip (Video2World)?

The benchmark samples from pure noise (Text2World), where a sample's turn comes from its seed and
prompt. A rollout starts from a real first frame of every camera, so the model only has to move
the scene. This takes held-out clips that drive straight (logged heading change under 5 degrees),
continues each for one window under the named ``left`` and ``right`` trajectories with the same
seed, the clip's own captions and speed, and reads the front camera's yaw with the eval's
dense-flow reader (drivewm.eval.trajectory.flow_fallback, the planar vehicle model; left positive)
over the whole rollout, the real first frame included.

    python studies/rollout_turns.py MODEL_DIR CLIPDIR [--clips 6] [--steps 20] [--seed 700] [--reproject 0.5]
        [--[no-]reproject-reshade]

Prints a row per clip: the yaw under each trajectory and their difference (left minus right:
positive where the model turns the way it is told); then the turn sign rate over all rollouts and
the mean difference. The warp is reshaded unless ``--no-reproject-reshade`` is given. About
40 s per rollout on 2 CPU cores. Numbers: git show a88b7a4:docs/quality-vs-compute.md, "Turns repeated".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from drivewm.clips.shards import iter_clips
from drivewm.eval.trajectory import flow_fallback
from drivewm.eval.trajectory_errors import heading_change_deg
from drivewm.generate.config import RECIPES
from drivewm.generate.rollout import rollout
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.model import MultiView
from drivewm.tokenizer import Tokenizer

STRAIGHT_DEG = 5.0


def straight_clips(clip_dir: Path, count: int) -> list:
    """The first straight clip of each shard (sorted), up to ``count``: one per drive, so the weather
    and the road vary."""
    out = []
    for shard in sorted(clip_dir.glob("*.tar")):
        for clip in iter_clips(shard):
            if clip.meta.ego_motion_known and abs(heading_change_deg(clip.T_world_from_ego)) < STRAIGHT_DEG:
                out.append(clip)
                break
        if len(out) == count:
            break
    return out


def front_yaw(sample) -> float:
    """Yaw (deg, left positive) the eval's flow reader sees in a sample's front camera; nan if unread."""
    videos = {n: sample.videos[i] for i, n in enumerate(sample.rig.names)}
    ego = flow_fallback(videos, sample.rig)
    return heading_change_deg(ego.T_world_from_ego[ego.registered]) if ego.registered.sum() >= 2 else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="a multi-view model folder, or shipped:multiview")
    parser.add_argument("clips", type=Path, help="a curated clip folder (held-out drives)")
    parser.add_argument("--clips", dest="count", type=int, default=6, help="how many straight clips")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--seed", type=int, default=700)
    parser.add_argument("--reproject", type=float, default=0.0, help="reprojected refinement sigma (0 = off)")
    parser.add_argument(
        "--reproject-reshade",
        action=argparse.BooleanOptionalAction,
        help="reshade the warp (drivewm.views.reshade; default on)",
    )
    args = parser.parse_args()

    model = MultiView.from_pretrained(resolve_model_folder(args.model))
    tokenizer = Tokenizer.from_pretrained(model.latent.tokenizer)
    yaws, diffs = {"left": [], "right": []}, []
    for j, clip in enumerate(straight_clips(args.clips, args.count)):
        row = {}
        for turn in ("left", "right"):
            settings = [f"trajectory={turn}", "rollout.windows=1", f"sampling.steps={args.steps}"]
            settings += [f"sampling.seed={args.seed + j}"]
            if args.reproject:
                steps = "[reproject,reshade]" if args.reproject_reshade is not False else "[reproject]"
                settings += [f"post_processing={steps}", f"reproject.sigma={args.reproject}"]
            row[turn] = front_yaw(rollout(model, clip, RECIPES.resolve(overrides=settings), tokenizer))
            yaws[turn].append(row[turn])
        diffs.append(row["left"] - row["right"])
        print(f"{clip.key:50s} left {row['left']:+6.1f}  right {row['right']:+6.1f}  difference {diffs[-1]:+6.1f} deg",
              flush=True)  # fmt: skip
    left, right = np.array(yaws["left"]), np.array(yaws["right"])
    signs = int((left > 0).sum() + (right < 0).sum())
    print(f"turn sign {signs} of {len(left) + len(right)}; mean yaw left {np.nanmean(left):+.1f}, "
          f"right {np.nanmean(right):+.1f} deg; mean difference {np.nanmean(diffs):+.1f} deg, "
          f"positive in {sum(d > 0 for d in diffs)} of {len(diffs)}")  # fmt: skip


if __name__ == "__main__":
    main()
