"""Sampling time per clip against the number of steps (EDM Heun and Euler with CFG), through the one
sampling function Text2World and multi-view models use (drivewm.diffusion.sampling.sample).

One clip is a 17-frame 192x320 video's latents (16, 5, 24, 40) under the 4x8x8 tokenizer, i.e.
1,200 tokens for a debug DiT at patch 2 (random weights: speed does not depend on them). Each
step costs 2 network evaluations with guidance (conditional + unconditional), Heun twice that
but one; the printed ratio is the measured time over (evaluations x one measured forward), so
1.0 means the sampler adds nothing on top of the network.

    python benchmarks/bench_sampling.py          # debug DiT, steps 5/10/20 (--steps 35 for Cosmos' default)
    python benchmarks/bench_sampling.py --full   # small preset (28M)
"""

from __future__ import annotations

import argparse
import time

import torch

from drivewm.diffusion.denoiser import Conditioning, EDMConfig, EDMDenoiser
from drivewm.diffusion.dit import DiT
from drivewm.diffusion.dit_config import DiTConfig, dit_preset
from drivewm.diffusion.samplers import SAMPLERS
from drivewm.diffusion.sampling import sample

LATENT = (16, 5, 24, 40)


@torch.no_grad()
def one_forward_s(denoiser: EDMDenoiser, cond: Conditioning, repeats: int = 3) -> float:
    x = torch.randn(1, *LATENT)
    denoiser(x, torch.ones(1), cond)  # warm-up
    times = []
    for _ in range(repeats):
        tic = time.process_time()  # CPU time: other processes on the machine disturb it far less than wall time
        denoiser(x, torch.ones(1), cond)
        times.append(time.process_time() - tic)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="small preset instead of debug")
    parser.add_argument("--steps", type=int, nargs="+", default=[5, 10, 20])
    parser.add_argument("--guidance", type=float, default=7.0)
    parser.add_argument("--threads", type=int, default=1, help="CPU intra-op threads")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    dit = DiT(DiTConfig(in_channels=16, **dit_preset("small" if args.full else "debug"))).eval()
    with torch.no_grad():  # non-zero outputs, so the sampler does real work
        dit.final.proj.weight.normal_(0, 0.02)
    denoiser = EDMDenoiser(dit, EDMConfig())
    cond = Conditioning(torch.randn(1, 32, 256), torch.ones(1, 32, dtype=torch.bool), torch.tensor([10.0]))
    fwd = one_forward_s(denoiser, cond)
    print(
        f"one forward: {fwd * 1e3:.0f} ms for {LATENT[1] * LATENT[2] * LATENT[3] // 4} tokens; guidance {args.guidance}"
    )
    print(f"{'sampler':8s} {'steps':>5s} {'evals':>5s} {'s/clip':>8s} {'ratio to evals x forward':>25s}")
    for name in SAMPLERS:
        for steps in args.steps:
            evals = (steps if name == "euler" else 2 * steps - 1) * (2 if args.guidance != 1 else 1)
            tic = time.process_time()
            sample(denoiser, cond, LATENT, [0], steps, args.guidance, name)  # what Text2World / MultiView run
            elapsed = time.process_time() - tic
            print(f"{name:8s} {steps:5d} {evals:5d} {elapsed:8.2f} {elapsed / (evals * fwd):25.2f}")


if __name__ == "__main__":
    main()
