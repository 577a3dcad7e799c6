"""Can the conditioning pathway carry the turn if it is trained hard? The trajectory probe's gap while
only the trajectory and camera encoders train at a high learning rate, the rest frozen, against the
whole network at post-training's rate.

The shipped multi-view model's waypoints move the denoising loss by about 0.1 % (studies/
trajectory_loss_gap.py). Both zero-initialised branches are small
(0.1M of 7M parameters) and learn at the backbone's rate; this asks whether they reach a larger gap
when they alone train, ten times as fast. Each step draws 2 clips of the cache that turn by more
than 5 degrees, with post-training's own loss (``MultiViewTask.loss``: one noise level per clip,
caption dropout, Video2World on half the steps; no trajectory dropout), and AdamW at a constant
rate. Every ``--probe-every`` steps it prints ``trajectory_loss_gap`` of the cache's first 8 clips
of ``--match`` turning more than 15 degrees (drivewm.multiview.trajectory_probe; those clips are
among the training draws, so this measures what the pathway can hold, not what generalises).

    python studies/trajectory_pathway.py drivewm/weights/multiview CACHE --train encoders --lr 1e-3
    python studies/trajectory_pathway.py drivewm/weights/multiview CACHE --train all --lr 1e-4

About 2.5 s a step on one thread at the shipped size (6 views of 5 x 12 x 20 latents, batch 2).
Numbers: git show a88b7a4:docs/quality-vs-compute.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from drivewm.multiview.data import MultiViewDataset
from drivewm.multiview.model import MultiView
from drivewm.multiview.posttrain import MultiViewTask, posttrain_config
from drivewm.multiview.trajectory_probe import loss_gap, turning_clips

#: Clips turning by more than this (degrees) are the training draws.
TRAIN_TURN_DEG = 5.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="a multi-view model folder (drivewm/weights/multiview for the shipped one)")
    parser.add_argument("cache", help="a latent cache folder of that model's tokenizer, with turning clips")
    parser.add_argument("--train", choices=("encoders", "all"), default="encoders")
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--probe-every", type=int, default=50)
    parser.add_argument("--match", default="intersection", help="the probe's clips: keys containing this")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model = MultiView.from_pretrained(args.model)
    ds = MultiViewDataset(args.cache, None, model.cfg.multiview.trajectory_waypoints, model.cfg.edm.sigma_data)
    task = MultiViewTask(posttrain_config("tiny", ["multiview.trajectory_dropout=0"]), ds, model)
    net = task.model
    draws = turning_clips(ds, len(ds), TRAIN_TURN_DEG)  # every distinct clip that turns
    probe = turning_clips(ds, 8, match=args.match)
    branches = [net.trajectory_encoder, net.camera_encoder]
    trained = list(net.parameters()) if args.train == "all" else [p for m in branches for p in m.parameters()]
    for p in net.parameters():
        p.requires_grad_(False)
    for p in trained:
        p.requires_grad_(True)
    print(
        f"{args.model}: training {sum(p.numel() for p in trained):,} of {sum(p.numel() for p in net.parameters()):,} "
        f"parameters ({args.train}) at lr {args.lr:g} on {len(draws)} clips turning > {TRAIN_TURN_DEG:g} deg; "
        f"probe: {len(probe)} {args.match} clips",
        flush=True,
    )
    opt = torch.optim.AdamW(trained, lr=args.lr, weight_decay=0.0)
    rng, losses, t0 = np.random.default_rng(args.seed), [], time.perf_counter()
    for step in range(args.steps + 1):
        if step % args.probe_every == 0:
            net.eval()
            gap, t = loss_gap(net, model, ds, probe)
            net.train()
            window = f"{np.mean(losses[-args.probe_every :]):.4f}" if losses else "-"
            print(
                f"step {step:5d}: trajectory_loss_gap {gap:+.5f} (t = {t:+.2f}), loss {window}, "
                f"{time.perf_counter() - t0:.0f} s",
                flush=True,
            )
        if step == args.steps:
            break
        indices = [int(i) for i in rng.choice(draws, 2, replace=False)]
        loss = task.loss(net, indices, [int(s) for s in rng.integers(1 << 30, size=2)], torch.device("cpu"))
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))


if __name__ == "__main__":
    main()
