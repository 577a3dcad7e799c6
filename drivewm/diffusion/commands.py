"""``drivewm pretrain`` and ``drivewm generate`` (thin: parse, build config, print it, call the library).

``generate`` dispatches on the model folder's ``model_type`` through :data:`GENERATORS`, so the
multi-view stage plugs its generator in by name (``drivewm.multiview.generate:generate``).
The models are imported inside the handlers, so that ``drivewm --help`` imports no PyTorch.
"""

from __future__ import annotations

import argparse
import importlib
import json
from pathlib import Path

from drivewm.choices import (
    add_guidance_interval_argument,
    add_registry_argument,
    at_least_one,
    model_folder,
    output_folder,
    seed,
)
from drivewm.diffusion.dit_config import DIT_PRESETS
from drivewm.multiview.commands import add_reproject_arguments
from drivewm.multiview.defaults import DEFAULT_BLEND, DEFAULT_SIGMA, DEFAULT_STITCH
from drivewm.recipe import add_recipe_arguments

#: model_type -> "module:function" taking (args) and returning an exit status or None.
GENERATORS = {
    "text2world": "drivewm.diffusion.commands:generate_text2world_command",
    "multiview": "drivewm.multiview.generate:generate_command",
}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("pretrain", help="train a Text2World diffusion model on tokenizer latents")
    add_recipe_arguments(p, DIT_PRESETS, "debug")
    p.add_argument(
        "--init", type=model_folder, help="Text2World folder whose weights start the run (warm start, fine-tuning)"
    )
    p.add_argument(
        "--data", required=True, type=Path, help="clip folder holding latents/NAME (or a latent cache folder)"
    )
    p.add_argument(
        "--tokenizer", type=model_folder, help="tokenizer model folder that encoded the latents (or shipped:tokenizer)"
    )
    p.add_argument(
        "--out", required=True, type=output_folder, help="model folder to write (resumes if it holds train_state.pt)"
    )
    p.add_argument(
        "--device",
        choices=["auto", "cpu", "cuda"],
        help="where to train (sets train.device; default: the recipe's, auto)",
    )
    p.set_defaults(func=pretrain_command)

    g = sub.add_parser("generate", help="generate clips from a Text2World or multi-view model")
    g.add_argument(
        "--model",
        type=model_folder,
        help="model folder (config.json + model.safetensors) or shipped:KIND; default: shipped:multiview",
    )
    g.add_argument("--prompt", required=True, action="append", help="caption (repeat for several)")
    g.add_argument(
        "--out", required=True, type=output_folder, help="output folder: clip shards, mp4s, contact_sheet.png"
    )
    g.add_argument("--steps", type=int, default=35, help="sampler steps")
    g.add_argument("--guidance", type=float, default=7.0, help="classifier-free guidance scale")
    add_guidance_interval_argument(g)
    g.add_argument("--seed", type=seed, default=0, help="sample i uses seed + i")
    g.add_argument("--num-samples", type=at_least_one, default=1, help="samples per prompt")
    add_registry_argument(
        g, "--sampler", "drivewm.diffusion.samplers:SAMPLERS", "EDM sampler (default heun)", default="heun"
    )
    g.add_argument(
        "--device", default="auto", choices=["auto", "cpu", "cuda"], help="where to sample (auto: CUDA when available)"
    )
    g.add_argument("--rig", help="camera rig (multi-view models)")
    g.add_argument("--trajectory", help="straight|left|right|stop|FILE (multi-view models)")
    g.add_argument("--condition-clip", type=Path, help="clip whose first frames condition the sample (Video2World)")
    g.add_argument(
        "--trajectory-guidance",
        type=float,
        default=1.0,
        help="multi-view models: weigh the trajectory's effect this many times (1 = plain conditioning; costs 2x)",
    )
    add_reproject_arguments(g, None, f"{DEFAULT_SIGMA:g}, off for Text2World models")
    g.add_argument(
        "--reproject-blend",
        action=argparse.BooleanOptionalAction,
        help="multi-view models: blend the first pass's first frame where the rig's cameras overlap before it is "
        f"reprojected, so the views agree there (default {'on' if DEFAULT_BLEND else 'off'}; never with "
        "--condition-clip; docs/quality-vs-compute.md, 'Cameras that disagree where they overlap')",
    )
    g.add_argument(
        "--stitch",
        action=argparse.BooleanOptionalAction,
        help="multi-view models: blend every decoded frame where the rig's cameras overlap, as a panorama is "
        f"stitched, so the views agree there in every frame (default {'on' if DEFAULT_STITCH else 'off'}; never "
        "with --condition-clip; docs/quality-vs-compute.md, 'Stitched: every frame blended')",
    )
    g.add_argument(
        "--prompt-template",
        action=argparse.BooleanOptionalAction,
        help="multi-view models: rewrite each prompt into the training captions' template (weather, time of day, "
        "road, traffic, the trajectory's manoeuvre and speed; other words dropped); on by default, "
        "--no-prompt-template samples the prompt as given",
    )
    g.set_defaults(func=generate_command, lock_out="generate")


def pretrain_command(args: argparse.Namespace) -> int:
    from drivewm.config import to_dict
    from drivewm.diffusion.pretrain import RECIPES, pretrain

    init = [f"init={args.init.resolve()}"] if args.init else []
    device = [f"train.device={args.device}"] if args.device else []
    cfg = RECIPES.resolve(args.preset, args.recipe, [*init, *args.overrides, *device])
    print(json.dumps(to_dict(cfg), indent=2))
    if args.dry_run:
        return 0
    last = pretrain(cfg, args.data, args.tokenizer, args.out)
    print(f"wrote {args.out} ({json.dumps(last)})")
    return 0


def generate_command(args: argparse.Namespace) -> int | None:
    from drivewm.errors import DrivewmError
    from drivewm.train.checkpoint import read_model_config

    if args.model is None:
        from drivewm.model_folders import shipped_model

        args.model = shipped_model("multiview")
    model_type = read_model_config(args.model).get("model_type")
    if model_type not in GENERATORS:
        raise DrivewmError(f"{args.model}: cannot generate from model_type {model_type!r}; known: {sorted(GENERATORS)}")
    module, func = GENERATORS[model_type].split(":")
    return getattr(importlib.import_module(module), func)(args)


def generate_text2world_command(args: argparse.Namespace) -> int:
    from drivewm.diffusion.generate import generate_text2world
    from drivewm.errors import DrivewmError

    multiview_only = args.rig or args.trajectory or args.condition_clip or args.reproject or args.reproject_walls
    multiview_only = multiview_only or args.prompt_template or args.reproject_reshade or args.reproject_blend
    multiview_only = multiview_only or args.stitch
    if multiview_only or args.trajectory_guidance != 1.0:  # None (not given) and off pass alike
        raise DrivewmError(
            f"{args.model}: a Text2World model takes no --rig/--trajectory/--condition-clip/--trajectory-guidance"
            "/--reproject/--reproject-walls/--reproject-reshade/--reproject-blend/--stitch/--prompt-template"
            " (multi-view models do)"
        )
    options = generate_options(args)
    files = generate_text2world(args.model, options, args.out)
    print(f"wrote {len(files)} files to {args.out}")
    return 0


def generate_options(args: argparse.Namespace):
    """The GenerateOptions of a ``drivewm generate`` command line."""
    from drivewm.diffusion.generate import GenerateOptions

    return GenerateOptions(
        args.prompt,
        args.steps,
        args.guidance,
        args.seed,
        args.num_samples,
        args.sampler,
        device=args.device,
        guidance_interval=args.guidance_interval,
    )
