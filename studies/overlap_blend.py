"""Do generated views agree where their cameras overlap if the first frame is blended there?

Reprojected refinement (drivewm.generate.reproject) warps every view's own first frame along the
trajectory, so where two cameras overlap each keeps the content its own first pass drew, and the
two need not agree: on the benchmark 19 % of generated camera pairs count towards CSE against the
held-out clips' 50 %. This blends the first frame of every view across the rig before the warp, as
a panorama is blended: every pixel's ray is followed to the road or to infinity (the warp's flat
world, drivewm.multiview.warp.ray_depths), looked up in every camera that sees that point, and the
colours are averaged, each camera weighted by the pixel's distance to that camera's image border
(feathering: a camera's own edge fades into its neighbour). Road and distant scenery then read
the same in both cameras of an overlap; the refinement starts from that.

The blend is drivewm.multiview.blend (``drivewm generate --reproject-blend``). On the validation
prompts of studies/reproject_sigma.py (none of them, nor their seeds, the benchmark's), two seeds
each, at generate's defaults otherwise, this writes the samples without the blend to ``OUT/own``
and with it to ``OUT/blend`` (the same first passes), for ``drivewm eval``:

    python studies/overlap_blend.py shipped:multiview --out OUT [--seeds 2] [--steps 20]
    drivewm eval OUT/own --out OUT/eval_own --reference HELDOUT_EVAL/metrics.json
    drivewm eval OUT/blend --out OUT/eval_blend --reference HELDOUT_EVAL/metrics.json

About 50 s per prompt and seed on 2 CPU cores. Numbers: studies/README.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from reproject_sigma import VALIDATION

from drivewm.generate.config import RECIPES
from drivewm.generate.protocol import GenerateRequest
from drivewm.generate.registry import load_generator
from drivewm.model_folders import resolve_model_folder


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="a multi-view model folder, or shipped:multiview")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--seeds", type=int, default=2, help="seeds per validation prompt")
    parser.add_argument("--steps", type=int, default=20, help="first-pass sampler steps (the benchmark's)")
    parser.add_argument("--guidance", type=float, default=7.0, help="caption guidance (the benchmark's)")
    args = parser.parse_args()
    model = resolve_model_folder(args.model)
    generator = load_generator(model, "cpu")
    for arm, steps in (("own", "[reproject,reshade]"), ("blend", "[reproject,reshade,blend]")):
        for prompt, turn, seed in VALIDATION:
            settings = [f"sampling.steps={args.steps}", f"sampling.guidance={args.guidance}", f"sampling.seed={seed}"]
            settings += [f"num_samples={args.seeds}", "rig=nuscenes6", f"trajectory={turn}", f"post_processing={steps}"]
            cfg = RECIPES.resolve(overrides=settings)
            generator.write(generator.generate(GenerateRequest([prompt]), cfg), args.out / arm / f"{turn}_{seed}")


if __name__ == "__main__":
    main()
