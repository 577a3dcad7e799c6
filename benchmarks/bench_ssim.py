"""SSIM speed: drivewm's band-matrix Gaussian filter against the grouped-convolution formulation.

``drivewm.tokenizer.metrics.ssim`` scores ``drivewm tokenizer eval`` (every view and frame of every
held-out clip) and is the structural term of the tokenizer's training loss. Its separable 11x11
Gaussian window is two products with band matrices; the formulation it replaced, and the one
pytorch-msssim and most SSIM code use, is two grouped ``conv2d`` calls (one group per channel).
Both give the same values to float rounding (checked here). Interleaved repeats, medians, one CPU
thread (as a training or eval worker runs), at two shapes: a 6-view 17-frame clip at 160x96 as
the eval scores it, and a training batch of 8 crops of 5 x 48 x 80 with its backward pass.

    python benchmarks/bench_ssim.py [--repeats 7] [--threads 1]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
import torch.nn.functional as F

from drivewm.tokenizer import metrics


def grouped_conv_blur(x: torch.Tensor, size: int) -> torch.Tensor:
    """The peer: separable Gaussian (valid) as two grouped convolutions, one group per channel."""
    k = x.shape[1]
    g = metrics._gaussian_1d(size).to(x)
    x = F.conv2d(x, g.view(1, 1, size, 1).expand(k, 1, size, 1), groups=k)
    return F.conv2d(x, g.view(1, 1, 1, size).expand(k, 1, 1, size), groups=k)


def timed(x: torch.Tensor, y: torch.Tensor, backward: bool) -> float:
    tic = time.perf_counter()
    out = metrics.ssim(y, x)
    if backward:
        out.backward()
    return time.perf_counter() - tic


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    band = metrics._blur
    cases = {
        "eval: 6 views x 17 frames, 160x96": ((6, 3, 17, 96, 160), False),
        "training loss: 8 crops x 5 frames, 48x80, + backward": ((8, 3, 5, 48, 80), True),
    }
    print(f"torch {torch.__version__}, {args.threads} thread(s), {args.repeats} interleaved repeats, medians")
    for name, (shape, backward) in cases.items():
        x = torch.rand(shape) * 2 - 1
        y = (x + 0.1 * torch.randn(shape)).clamp(-1, 1)
        if backward:
            y.requires_grad_(True)
        times = {"band matrices (drivewm)": [], "grouped conv2d": []}
        values = {}
        for _ in range(args.repeats):
            for label, blur in (("band matrices (drivewm)", band), ("grouped conv2d", grouped_conv_blur)):
                metrics._blur = blur
                try:
                    times[label].append(timed(x, y, backward))
                    values[label] = metrics.ssim(y, x).item()
                finally:
                    metrics._blur = band
        ours, peer = (statistics.median(t) for t in times.values())
        gap = abs(values["band matrices (drivewm)"] - values["grouped conv2d"])
        print(
            f"{name}: drivewm {ours * 1e3:.1f} ms, grouped conv2d {peer * 1e3:.1f} ms, "
            f"ratio {peer / ours:.2f}x faster; SSIM {values['grouped conv2d']:.6f}, |difference| {gap:.1e}"
        )


if __name__ == "__main__":
    main()
