"""Sampling speed of the AR transformer with and without the KV cache (drivewm.ar.sampling).

Samples ``--tokens`` tokens (default 1,000) from an empty prompt with a randomly initialised model of a
preset, once with the cache and once without, alternating rounds after a warm-up round
(benchmarks/interleaved.py), and prints the median seconds of each and the ratio: the issue's limit is
at least 10x at 1,000 tokens. Also checks that both drew the same tokens at the same seed.

    python benchmarks/bench_ar_kv_cache.py                      # debug preset, 1,000 tokens
    python benchmarks/bench_ar_kv_cache.py --preset tiny --repeats 3
"""

from __future__ import annotations

import argparse
import math

import torch
from interleaved import alternate, print_medians

from drivewm.ar.config import ARConfig, ar_preset
from drivewm.ar.model import ARCondition, ARTransformer
from drivewm.ar.sampling import sample_tokens
from drivewm.ar.sampling_config import TokenSampling

GRID_HW = [8, 12]  # a 96 x 64 view at 8x spatial compression


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="debug")
    parser.add_argument("--tokens", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    frames = math.ceil(args.tokens / (GRID_HW[0] * GRID_HW[1]))
    model = ARTransformer(ARConfig(**ar_preset(args.preset), grid_hw=GRID_HW, max_frames=frames)).eval()
    cond = ARCondition(
        torch.randn(1, 8, 256),
        torch.ones(1, 8, dtype=torch.bool),
        torch.randn(1, 96, 6),
        torch.zeros(1, frames, 3),
        torch.tensor([10.0]),
    )
    empty = torch.zeros(1, 0, dtype=torch.long)
    drawn = {}

    def run(cached: bool):
        def go(seed: int):
            drawn[cached] = sample_tokens(
                model,
                cond,
                empty,
                args.tokens,
                TokenSampling(top_k=100),
                torch.Generator().manual_seed(seed),
                use_cache=cached,
            )

        return go

    times = alternate({"kv_cache": run(True), "no_cache": run(False)}, args.repeats)
    print(f"{args.preset} preset, {args.tokens} tokens, {args.repeats} rounds, {args.threads} thread(s)")
    print_medians(times, "kv_cache", "seconds per sequence")
    print(f"same tokens with and without the cache (last round's seed): {torch.equal(drawn[True], drawn[False])}")


if __name__ == "__main__":
    main()
