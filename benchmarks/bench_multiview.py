"""Multi-view post-training throughput and peak memory per view count (1, 3, 6), and generation
time per 6-view clip, each as a ratio against its Text2World peer measured in the same run: the
parent model training / sampling the same views one by one (no cross-view attention, no camera or
trajectory conditioning). Every configuration runs in its own process so peak RSS is its own.

    python benchmarks/bench_multiview.py          # debug DiT, latents (16, 3, 12, 20) per view (180 tokens)
    python benchmarks/bench_multiview.py --full   # debug DiT, latents (16, 5, 24, 40) per view (1,200 tokens)

Peak memory is the process's peak RSS minus its RSS after building the model (ru_maxrss), i.e. the
training working set: activations, gradients and optimizer state.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def build(latent_shape: list[int], cross_view: str):
    import torch

    from drivewm.diffusion.dit_config import DiTConfig, dit_preset
    from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
    from drivewm.multiview.config import MultiViewConfig
    from drivewm.multiview.init import from_text2world

    torch.manual_seed(0)
    c = latent_shape[0]
    parent = Text2World(
        Text2WorldConfig(DiTConfig(in_channels=c, **dit_preset("debug"))),
        LatentInfo(latent_shape, [0.0] * c, [1.0] * c),
    )
    return parent, from_text2world(parent, MultiViewConfig(cross_view=cross_view), cond_frames=1)


def child(args: argparse.Namespace) -> dict:
    """One configuration: ``args.what`` in {mv, t2w} training or sampling ``args.views`` views."""
    import numpy as np
    import torch

    from drivewm.diffusion.denoiser import edm_loss
    from drivewm.geometry import load_rig
    from drivewm.multiview.trajectories import resolve_trajectory
    from drivewm.train.parallelize import apply_activation_checkpointing

    torch.set_num_threads(args.threads)
    parent, mv = build(args.latent, args.cross_view)
    rig = load_rig("nuscenes6").subset(load_rig("nuscenes6").names[: args.views])
    traj = resolve_trajectory("left", 16, 0.1)[None]
    caps = [[f"view {i} of a snowy highway" for i in range(args.views)]]
    if args.mode == "generate":
        start = time.perf_counter()
        if args.what == "mv":
            mv.sample_latents(rig, caps, traj, [0], steps=args.steps, guidance=1.0, sampler="euler")
        else:
            parent.sample_latents(caps[0], list(range(args.views)), steps=args.steps, guidance=1.0, sampler="euler")
        return {"seconds": time.perf_counter() - start}
    net = mv.net if args.what == "mv" else parent.denoiser
    if args.checkpointing:
        apply_activation_checkpointing(list(net.dit.blocks if args.what == "mv" else parent.dit.blocks))
    opt = torch.optim.AdamW(net.parameters(), lr=1e-4)
    cond = mv.conditioning(rig, caps, traj) if args.what == "mv" else parent.conditioning(caps[0])
    x0 = torch.randn(args.views, *args.latent)
    base = rss_mb()
    times = []
    for _ in range(args.steps + 1):
        tic = time.perf_counter()
        loss = edm_loss(
            net,
            mv.cfg.edm if args.what == "mv" else parent.cfg.edm,
            x0,
            cond,
            torch.full((args.views,), 1.0),
            torch.randn_like(x0),
            torch.ones(args.views, dtype=torch.bool),
        )
        loss.backward()
        opt.step()
        opt.zero_grad(set_to_none=True)
        times.append(time.perf_counter() - tic)
    c, t, h, w = args.latent
    tokens = args.views * t * (h // 2) * (w // 2)
    return {"tokens_per_s": tokens / float(np.median(times[1:])), "peak_mb": peak_mb() - base, "tokens": tokens}


def run(
    what: str,
    mode: str,
    views: int,
    latent: list[int],
    steps: int,
    cross_view: str = "neighbors",
    checkpointing: bool = False,
) -> dict:
    cmd = [
        sys.executable,
        __file__,
        "--child",
        "--what",
        what,
        "--mode",
        mode,
        "--views",
        str(views),
        "--steps",
        str(steps),
        "--cross-view",
        cross_view,
        "--latent",
        *map(str, latent),
    ] + (["--checkpointing"] if checkpointing else [])
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--full", action="store_true")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--what", default="mv")
    p.add_argument("--mode", default="train")
    p.add_argument("--views", type=int, default=1)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--cross-view", default="neighbors")
    p.add_argument("--checkpointing", action="store_true")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--latent", type=int, nargs=4, default=None)
    args = p.parse_args()
    if args.child:
        print(json.dumps(child(args)))
        return
    latent = [16, 5, 24, 40] if args.full else [16, 3, 12, 20]
    steps = 3
    print(f"debug DiT, latents {latent} per view, 1 thread, median of {steps} training steps (batch = 1 clip)")
    print(
        f"{'views':>5} {'mode':>16} {'tokens':>6} {'tok/s':>8} {'t2w tok/s':>9} {'ratio':>6} {'peak MB':>8} "
        f"{'t2w MB':>7} {'ratio':>6}"
    )
    for views, cross_view, ckpt in [
        (1, "neighbors", False),
        (3, "neighbors", False),
        (6, "neighbors", False),
        (6, "joint", False),
        (6, "neighbors", True),
    ]:
        mv = run("mv", "train", views, latent, steps, cross_view, ckpt)
        t2w = run("t2w", "train", views, latent, steps, checkpointing=ckpt)
        label = cross_view + ("+ckpt" if ckpt else "")
        print(
            f"{views:>5} {label:>16} {mv['tokens']:>6} {mv['tokens_per_s']:>8.0f} {t2w['tokens_per_s']:>9.0f} "
            f"{mv['tokens_per_s'] / t2w['tokens_per_s']:>6.2f} "
            f"{mv['peak_mb']:>8.0f} {t2w['peak_mb']:>7.0f} {mv['peak_mb'] / max(t2w['peak_mb'], 1):>6.2f}"
        )
    gen_steps = 10
    mv = run("mv", "generate", 6, latent, gen_steps)
    t2w = run("t2w", "generate", 6, latent, gen_steps)
    print(
        f"generation, one 6-view clip, {gen_steps} Euler steps: {mv['seconds']:.2f} s (Text2World, the same 6 views "
        "independently: "
        f"{t2w['seconds']:.2f} s; ratio {mv['seconds'] / t2w['seconds']:.2f})"
    )


if __name__ == "__main__":
    main()
