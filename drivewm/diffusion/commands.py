"""``drivewm pretrain`` (thin: parse, build config, print it, call the library); ``drivewm generate``
lives in drivewm.generate. The models are imported inside the handler, so that ``drivewm --help``
imports no PyTorch.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from drivewm.choices import (
    model_folder,
    output_folder,
)
from drivewm.diffusion.dit_config import DIT_PRESETS
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
