"""Does a trained multi-view model use the trajectory it is conditioned on, and which way round?

Sampling and reading the yaw back (the worldmodel benchmark's turn sign) needs dozens of samples to
tell a weak effect from chance. This asks the denoiser directly: the EDM loss of turning clips of a
latent cache (Text2World frames, fixed noise per clip) under their own waypoints, under the mirrored
ones (y -> -y: the other turn, the rays moving with it) and under none. A model that ignores the
trajectory has the same loss under all three; one that learned turns mirrored has a lower loss under
the mirrored waypoints. Captions are kept (as in training) or dropped (the trajectory alone).

    python studies/trajectory_loss_gap.py MODEL_DIR LATENT_CACHE [--clips 16] [--min-turn-deg 20] [--match roundabout]
        [--video2world] [--split] [--turned]

LATENT_CACHE: a folder of ``drivewm encode`` latents (the clips the model trained on, or held-out
ones). Prints, per noise level, the mean losses and "mirrored - true" with its t statistic over
clips (consecutive clips of one drive overlap, so it overstates the evidence) and the number of
clips whose own waypoints give the lower loss. Forward passes only: about a
minute for 16 clips on 2 CPU cores (``--split`` adds the own waypoints with the mirrored
moving-camera rays and the reverse: which of the two pathways carries the turn; ``--turned`` the
static rig's rays turned by a constant 20 degrees with and against each clip's turn: whether the
model reads a ray as a place in the rig, the layout of the road there; about 2 minutes each).
drivewm.multiview.trajectory_probe holds the probe; post-training logs the same gap as
``trajectory_loss_gap``. Numbers: git show a88b7a4:docs/quality-vs-compute.md.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from drivewm.multiview.data import MultiViewDataset
from drivewm.multiview.model import MultiView
from drivewm.multiview.trajectory_probe import SPLIT, TURNED, clip_losses, t_statistic, turning_clips


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="a multi-view model folder (drivewm/weights/multiview for the shipped one)")
    parser.add_argument("cache", help="a latent cache folder of that model's tokenizer")
    parser.add_argument("--clips", type=int, default=16)
    parser.add_argument("--min-turn-deg", type=float, default=20.0)
    parser.add_argument("--sigmas", default="0.3,1,3")
    parser.add_argument("--match", default="", help="only clips whose key contains this (e.g. a scenario)")
    parser.add_argument(
        "--video2world", action="store_true", help="give the first latent frame (as rollouts do): the rest is scored"
    )
    parser.add_argument(
        "--split",
        action="store_true",
        help="also score own waypoints with the mirrored moving-camera rays and the reverse: which pathway carries it",
    )
    parser.add_argument(
        "--turned",
        action="store_true",
        help="also score the static rig's rays turned 20 deg with and against each clip's turn: rays read as layout",
    )
    args = parser.parse_args()
    torch.set_grad_enabled(False)
    model = MultiView.from_pretrained(args.model)
    model.net.eval()
    ds = MultiViewDataset(args.cache, None, model.cfg.multiview.trajectory_waypoints, model.cfg.edm.sigma_data)
    clips = turning_clips(ds, args.clips, args.min_turn_deg, args.match)
    print(
        f"{args.model}: {len(clips)} clips{' of ' + args.match if args.match else ''} turning more than "
        f"{args.min_turn_deg:g} deg"
    )
    names = ("own", "mirrored", "none", *(SPLIT if args.split else ()), *(TURNED if args.turned else ()))
    for captions in (True, False):
        for sigma in (float(s) for s in args.sigmas.split(",")):
            r = np.array(
                [
                    clip_losses(
                        model.net, model, ds, i, sigma, captions, 1000 + j, names, cond_frames=int(args.video2world)
                    )
                    for j, i in enumerate(clips)
                ]
            )
            gap = r[:, 1] - r[:, 0]
            t = t_statistic(gap)
            print(
                f"captions {'kept   ' if captions else 'dropped'} sigma {sigma:4.1f}: loss own {r[:, 0].mean():.4f}, "
                f"mirrored {r[:, 1].mean():.4f}, none {r[:, 2].mean():.4f}; mirrored - own {gap.mean():+.5f} "
                f"(t = {t:+.2f}; own lower in {(gap > 0).sum()}/{len(gap)} clips)",
                flush=True,
            )
            for k, name in enumerate(names[3:], start=3):
                gap = r[:, k] - r[:, 0]
                print(
                    f"    {name}: minus own {gap.mean():+.5f} (t = {t_statistic(gap):+.2f}; "
                    f"below own in {(gap < 0).sum()}/{len(gap)} clips)",
                    flush=True,
                )


if __name__ == "__main__":
    main()
