"""What a multi-view post-training step spends outside the network: building the batch (latents read
from the cache, and per clip the conditioning: text, camera rays, waypoints, warp grids, and the noise warp)
with the clip cache off (``cache_clips=0``: every step builds every clip, as before the cache) and
warm (every clip built once before), beside the network's forward and backward on the same batch on
this CPU. Steps interleave the three; medians.

    python benchmarks/bench_posttrain_batch.py --data CLIPDIR [--init shipped:multiview] [--batch 32]

CLIPDIR holds a latent cache of the init's tokenizer (``drivewm tokenizer encode``). The batch work
is CPU work on the training thread whatever the device: on one H200 a step of the shipped model at
batch 32 took 0.19 s in all (docs/results.md), so the uncached batch time here is the
share of that step a GPU spent waiting.
"""

from __future__ import annotations

import argparse
import statistics
import time


class _AtNetwork(Exception):
    """Raised by the stand-in network: the batch is built."""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="clip folder with a latent cache")
    p.add_argument("--init", default="shipped:multiview", help="multi-view model folder (or shipped:multiview)")
    p.add_argument("--rig", default="nuscenes6")
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--steps", type=int, default=5, help="timed steps per variant (after one untimed)")
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args(argv)
    import torch

    from drivewm.choices import model_folder
    from drivewm.diffusion.dit import count_parameters
    from drivewm.multiview.posttrain import posttrain_config, posttrain_task
    from drivewm.train.loop import mix_seed

    torch.set_num_threads(args.threads)
    base = [f"rig={args.rig}", f"train.batch_size={args.batch}", "trajectory_probe_every=0"]
    cached = posttrain_task(posttrain_config("debug", base), model_folder(args.init), args.data)
    uncached = posttrain_task(posttrain_config("debug", [*base, "cache_clips=0"]), model_folder(args.init), args.data)
    n = cached.num_samples()
    print(
        f"{len(cached.dataset)} clips x {len(cached.dataset.camera_names)} views, latents "
        f"{cached.dataset.latent_shape}; model {count_parameters(cached.model) / 1e6:.2f}M parameters; "
        f"batch {args.batch}, {args.threads} thread(s)"
    )
    for i in range(n):  # warm the cache: every clip built once
        cached.prepared(cached.epoch_order()[i])
    cpu = torch.device("cpu")

    def batch_only(task, step):
        indices = [(step * args.batch + k) % n for k in range(args.batch)]
        seeds = [mix_seed(0, step, k) for k in range(args.batch)]

        def forward(*a, **k):  # stop at the network: everything before it is the batch work
            raise _AtNetwork

        tic = time.perf_counter()
        try:
            task.loss(forward, indices, seeds, cpu)
        except _AtNetwork:
            pass
        return time.perf_counter() - tic, indices, seeds

    times: dict[str, list[float]] = {"uncached": [], "cached": [], "network": []}
    for step in range(args.steps + 1):
        t_unc, indices, seeds = batch_only(uncached, step)
        t_c, _, _ = batch_only(cached, step)
        tic = time.perf_counter()
        loss = cached.loss(cached.model, indices, seeds, cpu)
        loss = loss[0] if isinstance(loss, tuple) else loss
        loss.backward()
        cached.model.zero_grad(set_to_none=True)
        t_net = time.perf_counter() - tic - t_c
        if step:  # the first step warms allocators and caches
            for k, v in zip(times, (t_unc, t_c, t_net)):
                times[k].append(v)
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f"batch work, cache off:  {med['uncached'] * 1000:8.1f} ms per step")
    less = med["uncached"] / med["cached"]
    print(f"batch work, cache warm: {med['cached'] * 1000:8.1f} ms per step  ({less:.1f}x less)")
    print(f"network fwd+bwd (CPU):  {med['network'] * 1000:8.1f} ms per step")
    print(f"batch work / network on this CPU: {med['uncached'] / med['network']:.3f} off, "
          f"{med['cached'] / med['network']:.3f} warm")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
