"""Did a fine-tune make the multi-view model better on clips it never saw, and does it use its waypoints more?

Sampling and scoring 24 clips takes a quarter of an hour on 2 cores and reads quality through the
eval's instruments; this asks the denoiser directly, with no sampling: the post-training loss of
every held-out clip at a few fixed noise draws (noise level, caption and Video2World draws seeded
per clip and draw, the trajectory always given), the same draws for every model, so that two models
are compared pair by pair. The second column is the trajectory probe (drivewm.multiview.trajectory_probe:
the loss of held-out turning clips under mirrored minus under their own waypoints, captions dropped;
> 0 = the trajectory is followed, with its t statistic over clips).

    python studies/heldout_loss.py MODEL_DIR [MODEL_DIR ...] --cache LATENT_CACHE [--clips 48] [--draws 4]

The first model is the reference of the paired differences. About 10 s per model per 48 clips on an
H200 and 2 minutes on 2 CPU cores. Numbers: studies/README.md.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.data import MultiViewDataset
from drivewm.multiview.model import MultiView
from drivewm.multiview.posttrain import RECIPES, MultiViewTask
from drivewm.multiview.trajectory_probe import loss_gap, turning_clips
from drivewm.train.loop import mix_seed


@torch.no_grad()
def heldout_losses(model: MultiView, ds: MultiViewDataset, clips: int, draws: int) -> np.ndarray:
    """(clips * draws,) post-training losses of ``clips`` clips spread evenly over ``ds`` (every drive
    and condition of a held-out cache), draw j of the k-th seeded ``mix_seed(777, k, j)``: the same
    noise for every model of one latent shape."""
    cfg = RECIPES.resolve("debug", None, ["multiview.trajectory_dropout=0", "multiview.layout_dropout=0"])
    task = MultiViewTask(cfg, ds, model)
    device = next(model.net.parameters()).device
    net = model.net.eval()
    with torch.autocast(device.type, dtype=torch.bfloat16, enabled=device.type == "cuda"):
        n = min(clips, len(ds))
        picked = [int(k * len(ds) / n) for k in range(n)]
        return np.array(
            [
                float(task.loss(net, [i], [mix_seed(777, k, j)], device))
                for k, i in enumerate(picked)
                for j in range(draws)
            ]
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", help="multi-view model folders (shipped:multiview for the shipped one)")
    parser.add_argument("--cache", required=True, help="a latent cache of held-out clips, of the models' tokenizer")
    parser.add_argument("--clips", type=int, default=48)
    parser.add_argument("--draws", type=int, default=4)
    parser.add_argument("--turns", type=int, default=16, help="held-out turning clips for the trajectory probe")
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    args = parser.parse_args()
    reference = None
    print("model | held-out loss | paired difference (s.e.) | clips x draws lower | mirrored - own (t, clips)")
    for name in args.models:
        model = MultiView.from_pretrained(resolve_model_folder(name)).to(args.device)
        ds = MultiViewDataset(args.cache, None, model.cfg.multiview.trajectory_waypoints, model.cfg.edm.sigma_data)
        losses = heldout_losses(model, ds, args.clips, args.draws)
        reference = losses if reference is None else reference
        diff = losses - reference
        turns = turning_clips(ds, args.turns)
        gap, t = loss_gap(model.net.eval(), model, ds, turns)
        print(
            f"{name} | {losses.mean():.4f} | {diff.mean():+.4f} ({diff.std() / np.sqrt(len(diff)):.4f}) | "
            f"{int((diff < 0).sum())}/{len(diff)} | {gap:+.4f} (t {t:.2f}, {len(turns)})"
        )


if __name__ == "__main__":
    main()
