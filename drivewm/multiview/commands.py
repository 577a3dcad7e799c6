"""``drivewm posttrain`` (thin: parse, build config, print it, call the library); multi-view
``drivewm generate`` and ``drivewm rollout`` live in drivewm.generate. The models are imported inside
the handler, so that ``drivewm --help`` imports no PyTorch."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from drivewm import resources
from drivewm.choices import (
    model_folder,
    output_folder,
)
from drivewm.diffusion.dit_config import DIT_PRESETS
from drivewm.recipe import add_recipe_arguments


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "posttrain", help="post-train a multi-view, trajectory-conditioned model from a Text2World model"
    )
    add_recipe_arguments(p, DIT_PRESETS, "debug", resources.names("recipes/posttrain"))
    p.add_argument(
        "--init",
        required=True,
        type=model_folder,
        help="Text2World folder to start from, or a multi-view folder to fine-tune (e.g. shipped:multiview)",
    )
    p.add_argument(
        "--data", required=True, type=Path, help="clip folder holding latents/NAME (or a latent cache folder)"
    )
    p.add_argument(
        "--rig", help="cameras to train on: rig name or YAML (default: the recipe's, else all cameras of the clips)"
    )
    p.add_argument(
        "--out", required=True, type=output_folder, help="model folder to write (resumes if it holds train_state.pt)"
    )
    p.add_argument(
        "--device",
        choices=["auto", "cpu", "cuda"],
        help="where to train (sets train.device; default: the recipe's, auto)",
    )
    p.set_defaults(func=posttrain_command)


def posttrain_command(args: argparse.Namespace) -> int:
    from drivewm.config import to_dict
    from drivewm.multiview.posttrain import RECIPES, posttrain

    overrides = [*([f"rig={args.rig}"] if args.rig else []), *args.overrides]
    overrides += [f"train.device={args.device}"] if args.device else []
    cfg = RECIPES.resolve(args.preset, args.recipe, overrides)
    print(json.dumps(to_dict(cfg), indent=2))
    if args.dry_run:
        return 0
    last = posttrain(cfg, args.init, args.data, args.out)
    print(f"wrote {args.out} ({json.dumps(last)})")
    return 0
