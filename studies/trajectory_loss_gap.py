"""Does a trained multi-view model use the trajectory it is conditioned on, and which way round?

Sampling and reading the yaw back (the worldmodel benchmark's turn sign) needs dozens of samples to
tell a weak effect from chance. This asks the denoiser directly: the EDM loss of turning clips of a
latent cache (Text2World frames, fixed noise per clip) under their own waypoints, under the mirrored
ones (y -> -y: the other turn, the rays moving with it) and under none. A model that ignores the
trajectory has the same loss under all three; one that learned turns mirrored has a lower loss under
the mirrored waypoints. Captions are kept (as in training) or dropped (the trajectory alone).

    python studies/trajectory_loss_gap.py MODEL_DIR LATENT_CACHE [--clips 16] [--min-turn-deg 20] [--match roundabout]

LATENT_CACHE: a folder of ``drivewm encode`` latents (the clips the model trained on, or held-out
ones). Prints, per noise level, the mean losses and "mirrored - true" with its t statistic over
clips (consecutive clips of one drive overlap, so it overstates the evidence) and the number of
clips whose own waypoints give the lower loss. Forward passes only: about a
minute for 16 clips on 2 CPU cores. Numbers: docs/quality-vs-compute.md.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import torch

from drivewm.diffusion.denoiser import edm_loss
from drivewm.eval.trajectory_errors import waypoint_heading_deg
from drivewm.multiview.data import MultiViewDataset
from drivewm.multiview.model import MultiView, build_conditioning


def turning_clips(ds: MultiViewDataset, count: int, min_turn_deg: float, match: str = "") -> list[int]:
    """Indices of the first ``count`` distinct clips whose key contains ``match`` and whose waypoints
    turn by more than ``min_turn_deg``."""
    seen, out = set(), []
    for i in range(len(ds)):
        key = ds.cache[i].meta.key
        if key not in seen and match in key and abs(waypoint_heading_deg(ds[i].trajectory)) > min_turn_deg:
            out.append(i)
        seen.add(key)
        if len(out) == count:
            break
    return out


def losses(model: MultiView, ds: MultiViewDataset, index: int, sigma: float, captions: bool, seed: int) -> list[float]:
    """EDM loss of one clip under its own, its mirrored and no trajectory (the same noise)."""
    s = ds[index]
    views = s.latents.shape[0]
    noise = torch.randn(s.latents.shape, generator=torch.Generator().manual_seed(seed))
    edm = dataclasses.replace(model.cfg.edm, cond_frames=0)
    mirrored = s.trajectory * np.array([1.0, -1.0, 1.0])
    out = []
    for traj in (s.trajectory, mirrored, None):
        cond = build_conditioning(model, s.rig, [s.view_captions], None if traj is None else traj[None], s.fps)
        keep = torch.full((views,), captions)
        out.append(float(edm_loss(model.net, edm, s.latents, cond, torch.full((views,), sigma), noise, keep)))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="a multi-view model folder (drivewm/weights/multiview for the shipped one)")
    parser.add_argument("cache", help="a latent cache folder of that model's tokenizer")
    parser.add_argument("--clips", type=int, default=16)
    parser.add_argument("--min-turn-deg", type=float, default=20.0)
    parser.add_argument("--sigmas", default="0.3,1,3")
    parser.add_argument("--match", default="", help="only clips whose key contains this (e.g. a scenario)")
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
    for captions in (True, False):
        for sigma in (float(s) for s in args.sigmas.split(",")):
            r = np.array([losses(model, ds, i, sigma, captions, 1000 + j) for j, i in enumerate(clips)])
            gap = r[:, 1] - r[:, 0]
            t = gap.mean() / (gap.std(ddof=1) / np.sqrt(len(gap)))
            print(
                f"captions {'kept   ' if captions else 'dropped'} sigma {sigma:4.1f}: loss own {r[:, 0].mean():.4f}, "
                f"mirrored {r[:, 1].mean():.4f}, none {r[:, 2].mean():.4f}; mirrored - own {gap.mean():+.5f} "
                f"(t = {t:+.2f}; own lower in {(gap > 0).sum()}/{len(gap)} clips)",
                flush=True,
            )


if __name__ == "__main__":
    main()
