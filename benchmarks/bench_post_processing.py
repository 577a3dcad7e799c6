"""Time of one multi-view ``drivewm generate`` clip with the ``reprojected`` recipe's post-steps
(reprojected refinement, the warp reshaded, the first frame blended, every frame stitched) against
generate's defaults (plain sampling, the network's own frames), end to end as the command runs it:
model and tokenizer loaded, sampling, decode, the post-steps, clip written.

The shipped multi-view model (or ``--model``), the world-model benchmark's sampler settings (20 Heun
steps, guidance 7, nuscenes6, a left turn). The two settings alternate, ``--repeats`` times each
after one warm-up round, and the medians are compared: the printed ratio is the post-processed time
over plain sampling's. Both are measured in the same run, so a busy machine slows both alike (say so
when quoting it).

    python benchmarks/bench_post_processing.py
    python benchmarks/bench_post_processing.py --steps 35 --repeats 5
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import torch
from interleaved import add_sampling_arguments, alternate, print_medians

from drivewm.generate.config import RECIPES
from drivewm.generate.protocol import GenerateRequest
from drivewm.generate.registry import load_generator
from drivewm.model_folders import resolve_model_folder
from drivewm.train.checkpoint import load_model_folder


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_sampling_arguments(parser)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    folder = resolve_model_folder(args.model)
    _, state = load_model_folder(folder, "multiview")
    params = sum(v.numel() for v in state.values() if v.is_floating_point())
    print(f"{args.model}: {params / 1e6:.2f}M parameters; {args.steps} Heun steps, guidance {args.guidance:g}")
    request = GenerateRequest(["light snow on a country lane, turning left"])

    def run(recipe: str):
        def clip(r: int) -> None:
            settings = [f"sampling.steps={args.steps}", f"sampling.guidance={args.guidance}", f"sampling.seed={r}"]
            cfg = RECIPES.resolve(None, recipe, [*settings, "rig=nuscenes6", "trajectory=left", "device=cpu"])
            print(f"{recipe}: post_processing {cfg.post_processing}")
            generator = load_generator(folder, cfg.device)
            with tempfile.TemporaryDirectory() as out:
                generator.write(generator.generate(request, cfg), Path(out))

        return clip

    times = alternate({"plain": run("default"), "reprojected": run("reprojected")}, args.repeats)
    print_medians(times, "plain", "setting")


if __name__ == "__main__":
    main()
