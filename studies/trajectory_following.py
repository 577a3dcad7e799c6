"""Does a debug multi-view model post-trained on the simulated clips follow the trajectory it is
conditioned on? A study, not a pytest test: at debug scale the answer is "not measurably", and this
script prints the numbers behind that statement (see the multiview report / drivewm/recipes/posttrain/README.md).

    python studies/trajectory_following.py CLIPDIR [--pool 16] [--steps 300]

Recipe: front camera of every simulated clip plus its mirror image (image flipped, trajectory
y -> -y: doubles the data and pairs every left turn with a right one), coded by the pooling
stand-in tokenizer (mv_standin.py), a random tiny Text2World parent, ``drivewm posttrain``'s task.
Then, for every turning clip (|final heading| > 0.15 rad), samples conditioned on its own and on
its mirrored trajectory (same seed), and three measurements:

1. the eval stage's estimator (pycolmap SfM, drivewm.eval.trajectory) on the decoded samples:
   frames registered (it already registers nothing on *real* frames pooled 4x or more);
2. yaw recovered by phase correlation of consecutive latent frames (scene shift / focal length):
   agreement with the conditioned vs the mirrored trajectory (chance = 0.5);
3. the conditional EDM loss of every clip with its own vs a shuffled vs its mirrored trajectory.
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import torch
from einops import rearrange

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "multiview"))  # the tests' helpers
from mv_standin import PoolTokenizer  # noqa: E402

from drivewm.clips import iter_clips  # noqa: E402
from drivewm.clips.latents import write_latent_clip, write_latent_index  # noqa: E402
from drivewm.diffusion.denoiser import edm_loss  # noqa: E402
from drivewm.diffusion.dit_config import DiTConfig  # noqa: E402
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig  # noqa: E402
from drivewm.multiview.data import MultiViewDataset  # noqa: E402
from drivewm.multiview.model import MultiView, build_conditioning  # noqa: E402
from drivewm.multiview.posttrain import posttrain, posttrain_config  # noqa: E402

MIRROR_Y = np.array([1.0, -1.0, 1.0])


def mirrored_cache(clip_dir: Path, out: Path, tok: PoolTokenizer) -> tuple[int, ...]:
    """Front-camera latents of every clip and of its mirror image; returns the latent shape."""
    rows = []
    for clip in iter_clips(clip_dir):
        for mirror in (False, True):
            v = clip.video("CAM_FRONT")[:, :, ::-1].copy() if mirror else clip.video("CAM_FRONT")
            z = tok.encode(rearrange(torch.from_numpy(v).float() / 127.5 - 1, "t h w c -> 1 c t h w"))
            traj = np.asarray(clip.meta.trajectory_ego) * (MIRROR_Y if mirror else 1.0)
            rig = clip.meta.get_rig().subset(["CAM_FRONT"]).to_dict()
            meta = dataclasses.replace(
                clip.meta, key=clip.key + ("-m" if mirror else ""), trajectory_ego=traj.tolist(), rig=rig
            )
            rows.append(write_latent_clip(out, meta, z, clip.T_world_from_ego))
    write_latent_index(out, {"path": None, "latent_mean": [0.0] * 3, "latent_std": [0.5] * 3}, rows)
    return tuple(z.shape[1:])


def heading_rad(waypoints: np.ndarray) -> float:
    d = waypoints[-1] - waypoints[-2]
    return float(np.arctan2(d[1], d[0]))


def phase_yaw_rad(z: torch.Tensor, pool: int, focal_px: float) -> float:
    """Yaw change over a clip from latents (c, t, h, w): summed horizontal shift of the upper half
    (distant scene: rotation dominates) between consecutive latent frames, over the focal length."""
    g = z.mean(0).double().numpy()
    top = g.shape[1] // 2
    return sum(cv2.phaseCorrelate(g[i, :top], g[i + 1, :top])[0][0] for i in range(len(g) - 1)) * pool / focal_px


def sfm_registered(model: MultiView, z: torch.Tensor, tok: PoolTokenizer, rig) -> int:
    from drivewm.eval.trajectory import estimate_ego_trajectory

    video = tok.decode(z[None])[0]
    frames = ((rearrange(video, "c t h w -> t h w c").clamp(-1, 1) + 1) * 127.5).round().byte().numpy()
    try:
        return int(estimate_ego_trajectory({"CAM_FRONT": frames}, rig).registered.sum())
    except Exception:  # the estimator raises when nothing reconstructs
        return 0


def conditional_losses(model: MultiView, ds: MultiViewDataset) -> np.ndarray:
    """(N, 3) EDM loss of each clip with its own, a shuffled and its mirrored trajectory (captions dropped)."""
    edm, sigmas = dataclasses.replace(model.cfg.edm, cond_frames=0), torch.tensor([0.2, 0.5, 1.0, 2.0])
    rng, out = np.random.default_rng(0), []
    for i in range(len(ds)):
        s, other = ds[i], ds[int((i + 1 + rng.integers(len(ds) - 1)) % len(ds))]
        row = []
        for traj in (s.trajectory, other.trajectory, s.trajectory * MIRROR_Y):
            cond = build_conditioning(model, s.rig, [s.view_captions] * 4, np.stack([traj] * 4), s.fps)
            noise = torch.randn((4, *s.latents.shape[1:]), generator=torch.Generator().manual_seed(i))
            with torch.no_grad():
                row.append(
                    float(
                        edm_loss(
                            model.net,
                            edm,
                            s.latents.repeat(4, 1, 1, 1, 1),
                            cond,
                            sigmas,
                            noise,
                            torch.zeros(4, dtype=torch.bool),
                        )
                    )
                )
        out.append(row)
    return np.array(out)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("clip_dir", type=Path)
    p.add_argument("--pool", type=int, default=16)
    p.add_argument("--steps", type=int, default=300)
    args = p.parse_args()
    torch.set_num_threads(1)
    root = Path(tempfile.mkdtemp(prefix="mv_study_"))
    tok = PoolTokenizer(args.pool)
    c, t, h, w = mirrored_cache(args.clip_dir, root / "latents", tok)
    torch.manual_seed(0)
    parent = Text2World(
        Text2WorldConfig(DiTConfig(in_channels=c, hidden_dim=64, depth=3, num_heads=4, adaln_lora_dim=16)),
        LatentInfo([c, t, h, w], [0.0] * c, [0.5] * c, 10.0, None, {}),
    )
    parent.save_pretrained(root / "t2w")
    cfg = posttrain_config(
        "debug",
        [
            f"train.steps={args.steps}",
            "train.batch_size=4",
            "train.lr=0.001",
            "train.checkpoint_every=100000",
            "train.log_every=50",
            "sample_steps=2",
        ],
    )
    print("post-training:", posttrain(cfg, root / "t2w", root / "latents", root / "mv"))
    model = MultiView.from_pretrained(root / "mv")
    ds = MultiViewDataset(root / "latents", None, 16)
    focal = float(ds[0].rig.cameras[0].K[0, 0])
    rows = []
    for i in range(len(ds)):
        s = ds[i]
        if abs(heading_rad(s.trajectory)) < 0.15:
            continue
        zs = [
            model.sample_latents(s.rig, [s.view_captions], tr[None], [i], steps=12, guidance=0.0)[0, 0]
            for tr in (s.trajectory, s.trajectory * MIRROR_Y)
        ]
        real = phase_yaw_rad(ds.cache[i].latents[0], args.pool, focal)
        rows.append(
            (
                heading_rad(s.trajectory),
                real,
                *(phase_yaw_rad(z, args.pool, focal) for z in zs),
                *(sfm_registered(model, z, tok, s.rig) for z in zs),
            )
        )
        print(
            "{:<28s} heading {:+.2f}  real-clip yaw {:+.2f}  sample yaw (own {:+.2f}, mirrored {:+.2f})  "
            "SfM registered {}, {} of {}".format(ds.cache.rows[i]["key"], *rows[-1], tok.decode(zs[0][None]).shape[2])
        )
    r = np.array(rows)
    agree = np.concatenate(
        [np.abs(r[:, 2] - r[:, 0]) < np.abs(r[:, 2] + r[:, 0]), np.abs(r[:, 3] + r[:, 0]) < np.abs(r[:, 3] - r[:, 0])]
    )
    print(
        f"phase-correlation yaw agrees with the conditioned (not the mirrored) trajectory: {agree.mean():.2f} of "
        f"{len(agree)} (chance 0.5)"
    )
    losses = conditional_losses(model, ds)
    print(
        "EDM loss own {:.4f} shuffled {:.4f} mirrored {:.4f}; own < shuffled in {:.2f}, own < mirrored in {:.2f} "
        "of {} clips".format(
            *losses.mean(0), np.mean(losses[:, 0] < losses[:, 1]), np.mean(losses[:, 0] < losses[:, 2]), len(losses)
        )
    )
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
