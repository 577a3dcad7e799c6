"""Time of one multi-view ``drivewm generate`` clip at its defaults (the prompt template, reprojected
refinement from ``DEFAULT_SIGMA``, the warp reshaded by ``DEFAULT_RESHADE``, the first frame blended
and every frame stitched where the cameras overlap) against plain sampling from noise
(``--no-prompt-template --reproject 0 --no-stitch``), end to end as the command runs it: model and
tokenizer loaded, first pass, decode, blend, warp, reshade, encode, refinement, decode, stitch, clip
written.

The shipped multi-view model (or ``--model``), the world-model benchmark's sampler settings (20 Heun
steps, guidance 7, nuscenes6, a left turn). The two settings alternate, ``--repeats`` times each
after one warm-up round, and the medians are compared: the printed ratio is the default's time over
plain sampling's. Both are measured in the same run, so a busy machine slows both alike (say so when
quoting it).

    python benchmarks/bench_generate_defaults.py
    python benchmarks/bench_generate_defaults.py --steps 35 --repeats 5
"""

from __future__ import annotations

import argparse
import tempfile

import torch
from interleaved import add_sampling_arguments, alternate, print_medians

from drivewm.diffusion.generate import GenerateOptions
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.defaults import DEFAULT_BLEND, DEFAULT_RESHADE, DEFAULT_SIGMA, DEFAULT_STITCH
from drivewm.multiview.generate import generate_multiview
from drivewm.multiview.reproject import Reprojection
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
    default = f"template + reprojection from {DEFAULT_SIGMA:g}{', reshaded' if DEFAULT_RESHADE else ''}, 10 steps"
    default += (", first frame blended" if DEFAULT_BLEND else "") + (", stitched" if DEFAULT_STITCH else "")
    print(f"{torch.get_num_threads()} threads; default: {default}")
    prompt = "light snow on a country lane, turning left"

    def run(reprojection: Reprojection | None, template: bool, stitch: bool | None):
        def clip(r: int) -> None:
            options = GenerateOptions([prompt], args.steps, args.guidance, seed=r, device="cpu")
            with tempfile.TemporaryDirectory() as out:
                generate_multiview(folder, options, "nuscenes6", "left", None, out, 1.0, reprojection, template, stitch)

        return clip

    arms = {"plain": run(Reprojection(0.0), False, False), "default": run(None, True, None)}
    times = alternate(arms, args.repeats)
    print_medians(times, "plain", "setting")


if __name__ == "__main__":
    main()
