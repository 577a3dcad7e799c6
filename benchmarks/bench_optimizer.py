"""AdamW step time of the shared training loop's optimizer: per-parameter loop, foreach and fused kernels.

The loop (drivewm/train/loop.py) builds its AdamW with :func:`drivewm.train.loop.adamw_impl`; this
script measures why. For each model (the DiT presets' parameter sets, random gradients) every
implementation takes one ``optimizer.step()`` per round; rounds interleave the implementations so a
shared machine's noise hits all alike, and the median over rounds counts (process CPU time on a CPU,
wall time on CUDA). Prints parameter counts, milliseconds per step, and each implementation's ratio
to the fastest, plus the largest difference of the updated weights from the per-parameter loop's
(the implementations compute the same update up to rounding).

    python benchmarks/bench_optimizer.py                    # tiny and small DiT presets
    python benchmarks/bench_optimizer.py --presets base --rounds 5
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from drivewm.diffusion.dit import DiT, count_parameters
from drivewm.diffusion.dit_config import DiTConfig, dit_preset
from drivewm.train.loop import adamw_impl

IMPLS = {"loop": dict(foreach=False), "foreach": dict(foreach=True), "fused": dict(fused=True)}


def _clock(device: torch.device) -> float:
    if device.type == "cuda":
        torch.cuda.synchronize()
        return time.perf_counter()
    return time.process_time()


def bench_preset(preset: str, rounds: int, device: torch.device) -> None:
    torch.manual_seed(0)
    model = DiT(DiTConfig(**dit_preset(preset))).to(device)
    params = [p for p in model.parameters() if p.requires_grad]
    grads = [torch.randn_like(p) * 1e-3 for p in params]
    copies = {name: [p.detach().clone().requires_grad_(True) for p in params] for name in IMPLS}
    opts = {name: torch.optim.AdamW(copies[name], lr=1e-4, weight_decay=0.01, **kw) for name, kw in IMPLS.items()}
    times = {name: [] for name in IMPLS}
    for _ in range(rounds + 1):  # the first round warms up (state allocation)
        for name, opt in opts.items():
            for p, g in zip(copies[name], grads, strict=True):
                p.grad = g
            tic = _clock(device)
            opt.step()
            times[name].append(_clock(device) - tic)
    med = {name: statistics.median(t[1:]) for name, t in times.items()}
    best = min(med.values())
    drift = {
        name: max(float((a - b).detach().abs().max()) for a, b in zip(copies[name], copies["loop"], strict=True))
        for name in IMPLS
    }
    print(f"{preset}: {count_parameters(model) / 1e6:.2f}M parameters in {len(params)} tensors, {rounds} rounds")
    for name in IMPLS:
        ratio = med[name] / best
        print(f"  {name:8s} {med[name] * 1e3:8.2f} ms/step  {ratio:5.2f}x the fastest  max|dw-loop| {drift[name]:.1e}")
    print(f"  the loop uses: {adamw_impl(params)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default="tiny,small", help="comma-separated DiT presets")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    args = ap.parse_args()
    torch.set_num_threads(1)
    for preset in args.presets.split(","):
        bench_preset(preset, args.rounds, torch.device(args.device))


if __name__ == "__main__":
    main()
