"""Does a debug multi-view model post-trained on simulated clips follow the trajectory it is
conditioned on, judged by the eval stage's estimator? A study (prints numbers), not a pytest test:
measured at debug scale on CPU the answer is "no better than chance" (see the numbers at the end).

    python studies/turned_following.py CLIPDIR [--steps 300] [--lr 1e-3] [--batch-size 4]

Set-up, and why each part is there:

- Data: the front camera of the simulated clips, each as copies turned left and right by an extra
  yaw rate and an unturned one (yaw_augment.py: trajectory rebuilt, frames re-rendered by the
  rotation homography). All copies of a clip share frame 0.
- Training: ``drivewm posttrain``'s task from a random tiny Text2World parent with Video2World on
  every step (``multiview.video2world_prob=1``, ``cond_frames=1``): frame 0 says where the car is,
  only the trajectory (per-latent-frame Plucker rays + the waypoint MLP) says where it turns, so a
  model that ignores it cannot tell the copies apart.
- Latents: the pooling stand-in tokenizer (mv_standin.py) at 8x, decoded bilinearly. The eval
  estimator (dense-flow method; SfM leaves such frames unregistered) is checked on the same decode
  of the real turned frames in test_turned_clips.py: it ranks the left copy above the right one
  for 12 of 12 clips, so it can judge samples at this resolution.
- Measure: each clip sampled under its left- and its right-turned trajectory with one seed; a pair
  agrees when the recovered yaws fit their own trajectories better than the swapped ones
  (yaw_augment.paired_agreement). A model that ignores the trajectory scores 0 (identical samples),
  one that responds at random 1/2; one-sided binomial p against 1/2. Also the conditional EDM
  loss with each clip's own vs its swapped trajectory.

Measured (12 clips, rate 0.25 rad/s, 24 turned copies + 12 unturned; CPU, 1 thread):

| training | sampling | pairs agreeing (p) | EDM loss own / swapped, sigma 1 and 5 |
| --- | --- | --- | --- |
| 600 steps, lr 1e-3, p_mean -1.2 | 8 Heun, text-uncond. | 4 / 12 (0.93) | own lower for 71-96 % of copies, by ~1 % |
| 1200 steps, lr 2e-3, p_mean -1.2 | 8 Heun, text-uncond. | 8 / 12 (0.19) | own lower for 71-96 %, by 1-2 % |
| 1200 steps, lr 2e-3, p_mean 0.5 | 8 Heun, text-uncond. | 9 / 12 (0.073) | 0.137 / 0.187 and 0.174 / 0.315, own lower for 24 / 24 |
| same | 8 / 4 / 2 Heun, 2 seeds | 12 / 24 (0.58), 12 / 24 (0.58), 16 / 24 (0.076) | same |
| 2000 steps, lr 2e-3, p_mean 0.5 | 8 Heun, text-uncond., 2 seeds | 14 / 24 (0.27) | 0.110 / 0.205 and 0.129 / 0.369, own lower for 24 / 24 |

So with Video2World on every step and the training noise centred higher, the model *uses* the
trajectory (its denoising loss with its own trajectory is 27-65 % lower than with the swapped one
at sigma >= 1, for every copy), but its 1.6 s samples do not carry the turn into a motion the eval
estimator recovers better than chance: the seed decides the recovered yaw more than the
trajectory.

Second round (same set-up unless named; 9 or 12 clips):

| change | pairs agreeing |
| --- | --- |
| trajectory dropout 0.1 (new default) + trajectory guidance 1 / 3 / 6 (``--trajectory-guidance``), 1200 steps, p_mean 0.5, 9 clips | 5/9, 5/9, 3/9 |
| + reprojected first frame (``--set multiview.warp_condition=true``, plane at infinity), 800 steps, p_mean -1.2, 8 / 16 Heun steps x guidance 1 / 3 | 4, 5, 6, 5 of 12 |
| same model, sampling stopped at sigma_min 0.5 / 1.0 (smooth samples), guidance 1 / 3 | 6, 3, 8, 3 of 12 |
| 16x pooling instead of 8x (smoother, easier to model) | the estimator ranks the *real* turned copies 6/12: no judge there |

Why: the contact sheets of these runs show the samples themselves are patch-sized noise around a
blurry mean (a 3-block, 64-wide DiT after ~1000 CPU steps), so the recovered yaw is the
estimator reading noise. At sigma 5 the model's denoising loss (0.18-0.21) already beats copying
the first frame (0.45 turned / 0.32 real clips), the reprojected first frame (0.32-0.37 / 0.33)
and the clip mean (0.49): at 8x pooling and 18 m/s most of what changes in 1.6 s is the road
texture rushing past, which no warp of the first frame predicts, so conditioning is not the limit,
the model's capacity and training time are. "Follows trajectories better than chance" stays
undemonstrated on this machine; the run that should settle it is a GPU post-training of the
``small`` preset on a few hundred simulated clips, judged by this script.
"""  # noqa: E501 (tables of measurements)

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "multiview"))  # the tests' helpers
from yaw_augment import (  # noqa: E402
    decode_bilinear,
    paired_agreement,
    recovered_yaw,
    trajectory_yaw,
    turned_key,
    write_turned_cache,
)

from drivewm.diffusion.denoiser import EDMConfig, edm_loss  # noqa: E402
from drivewm.diffusion.dit_config import DiTConfig  # noqa: E402
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig  # noqa: E402
from drivewm.multiview.data import MultiViewDataset  # noqa: E402
from drivewm.multiview.model import MultiView, build_conditioning  # noqa: E402
from drivewm.multiview.posttrain import posttrain, posttrain_config  # noqa: E402


def train_model(
    latent_dir: Path,
    root: Path,
    steps: int,
    lr: float,
    batch_size: int,
    p_mean: float = -1.2,
    overrides: list[str] | None = None,
) -> MultiView:
    """A tiny random Text2World parent (patch 4 on the (3, 5, 24, 40) latents) post-trained with
    Video2World on every step. ``p_mean``: centre of the training ln(sigma) (EDM default -1.2;
    higher puts the training on the noise levels where the motion is decided, not read off the input)."""
    torch.manual_seed(0)
    dit = DiTConfig(in_channels=3, patch_size=4, hidden_dim=64, depth=3, num_heads=4, adaln_lora_dim=16)
    parent = Text2World(
        Text2WorldConfig(dit, EDMConfig(p_mean=p_mean)),
        LatentInfo([3, 5, 24, 40], [0.0] * 3, [0.5] * 3, 10.0, None, {}),
    )
    parent.save_pretrained(root / "t2w")
    cfg = posttrain_config(
        "debug",
        [
            f"train.steps={steps}",
            f"train.batch_size={batch_size}",
            f"train.lr={lr}",
            "train.warmup_steps=20",
            "train.checkpoint_every=100000",
            "train.log_every=100",
            "sample_steps=2",
            "multiview.video2world_prob=1.0",
            "cond_frames=1",
            *(overrides or []),
        ],
    )
    posttrain(cfg, root / "t2w", latent_dir, root / "mv")
    return MultiView.from_pretrained(root / "mv")


def turned_pairs(ds: MultiViewDataset, rate: float) -> list[tuple[int, int]]:
    """(index of the +rate copy, index of the -rate copy) of every clip."""
    by_key = {ds.cache.rows[i]["key"]: i for i in range(len(ds))}
    return [
        (i, by_key[k.replace(turned_key("", rate), turned_key("", -rate))])
        for k, i in sorted(by_key.items())
        if k.endswith(turned_key("", rate))
    ]


def sampled_pairs(
    model: MultiView, ds: MultiViewDataset, rate: float, steps: int, seeds: int = 1, trajectory_guidance: float = 1.0
) -> list[tuple[float, float, float, float]]:
    """Per clip and seed: (conditioned yaw left, right, recovered yaw left, right); both samples from
    the same seed and the clip's own frame 0 (Video2World)."""
    out = []
    jobs = [(pair, k * 1000 + c) for k in range(seeds) for c, pair in enumerate(turned_pairs(ds, rate))]
    for pair, n in jobs:
        s = ds[pair[0]]
        rec = []
        for i in pair:
            z = model.sample_latents(
                s.rig,
                [s.view_captions],
                ds[i].trajectory[None],
                [n],
                steps=steps,
                guidance=1.0,
                cond_latents=ds.cache[i].latents[None],
                trajectory_guidance=trajectory_guidance,
            )[0, 0]
            rec.append(recovered_yaw(decode_bilinear(z), s.rig.cameras[0]))
        out.append((trajectory_yaw(ds[pair[0]].trajectory), trajectory_yaw(ds[pair[1]].trajectory), *rec))
        print(
            "{:<28s} conditioned yaw {:+.2f} / {:+.2f}  recovered {:+.2f} / {:+.2f}".format(
                ds.cache.rows[pair[0]]["key"], *out[-1]
            )
        )
    return out


def conditional_losses(model: MultiView, ds: MultiViewDataset, rate: float, sigma: float) -> np.ndarray:
    """(N, 2) Video2World EDM loss of every turned copy with its own and with its swapped trajectory."""
    rows = []
    for pair in turned_pairs(ds, rate):
        for a, b in (pair, pair[::-1]):
            s, row = ds[a], []
            for traj in (ds[a].trajectory, ds[b].trajectory):
                cond = build_conditioning(model, s.rig, [s.view_captions] * 4, np.stack([traj] * 4), s.fps)
                noise = torch.randn((4, *s.latents.shape[1:]), generator=torch.Generator().manual_seed(a))
                with torch.no_grad():
                    row.append(
                        float(
                            edm_loss(
                                model.net,
                                model.cfg.edm,
                                s.latents.repeat(4, 1, 1, 1, 1),
                                cond,
                                torch.full((4,), sigma),
                                noise,
                                torch.ones(4, dtype=torch.bool),
                            )
                        )
                    )
            rows.append(row)
    return np.array(rows)


def main() -> None:
    from scipy.stats import binomtest

    p = argparse.ArgumentParser()
    p.add_argument("clip_dir", type=Path)
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--batch-size", type=int, default=4)
    p.add_argument("--sample-steps", type=int, nargs="+", default=[8], help="sampler steps (one measurement each)")
    p.add_argument("--seeds", type=int, default=1, help="sample pairs per clip")
    p.add_argument("--p-mean", type=float, default=-1.2, help="centre of the training ln(sigma)")
    p.add_argument(
        "--trajectory-guidance", type=float, nargs="+", default=[1.0], help="trajectory guidance scales to sample with"
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="post-training override, e.g. multiview.frame_motion=false",
    )
    p.add_argument("--rate", type=float, default=0.25, help="extra yaw rate (rad/s) of the turned copies")
    args = p.parse_args()
    torch.set_num_threads(1)
    root = Path(tempfile.mkdtemp(prefix="mv_turned_"))
    latents = write_turned_cache(args.clip_dir, root / "latents", (-args.rate, 0.0, args.rate))
    model = train_model(latents, root, args.steps, args.lr, args.batch_size, args.p_mean, args.overrides)
    ds = MultiViewDataset(latents, None, model.cfg.multiview.trajectory_waypoints, model.cfg.edm.sigma_data)
    for steps, w in [(s, w) for s in args.sample_steps for w in args.trajectory_guidance]:
        pairs = sampled_pairs(model, ds, args.rate, steps, seeds=args.seeds, trajectory_guidance=w)
        hits = paired_agreement(pairs)
        print(
            f"{steps} Heun steps, trajectory guidance {w}: pairs whose recovered yaws fit their own trajectories "
            f"better than the swapped ones: {hits} of "
            f"{len(pairs)} (random response 1/2; one-sided binomial p = "
            f"{binomtest(hits, len(pairs), 0.5, alternative='greater').pvalue:.3f})"
        )
    for sigma in (0.2, 1.0, 5.0):
        losses = conditional_losses(model, ds, args.rate, sigma)
        print(
            f"sigma {sigma}: Video2World EDM loss own {losses[:, 0].mean():.4f} swapped {losses[:, 1].mean():.4f}; "
            f"own < swapped for {np.mean(losses[:, 0] < losses[:, 1]):.2f} of {len(losses)}"
        )
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
