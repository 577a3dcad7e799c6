"""``drivewm ar train|eval`` (heavy imports inside the handlers; the recipe book is light).

Generation from an AR model folder goes through ``drivewm generate`` / ``drivewm rollout``, which choose
drivewm.ar.generator by the folder's model type.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drivewm.ar.config import AR_PRESETS
from drivewm.choices import at_least_one, model_folder, output_folder, whole_number
from drivewm.recipe import add_recipe_arguments


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ar", help="autoregressive world model on FSQ tokens: train, evaluate")
    asub = p.add_subparsers(dest="ar_command", metavar="ACTION", required=True)

    t = asub.add_parser(
        "train",
        help="train (or resume) an AR model on the latent cache of an FSQ tokenizer",
        description="A preset is a size (--preset tiny); override any field with --set, e.g. --set train.steps=2000.",
    )
    add_recipe_arguments(t, AR_PRESETS, "debug")
    t.add_argument("--data", required=True, type=Path, help="clip folder holding latents/NAME (or a latent cache)")
    t.add_argument("--tokenizer", required=True, type=model_folder, help="the FSQ tokenizer that encoded the cache")
    t.add_argument("--out", required=True, type=output_folder, help="model folder; rerun with the same --out to resume")
    t.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto", help="where to train")
    t.set_defaults(func=_train)

    e = asub.add_parser("eval", help="held-out bits per token against the copy and unigram baselines")
    e.add_argument("--model", required=True, type=model_folder, help="AR model folder")
    e.add_argument("--data", required=True, type=Path, help="clip folder holding latents/NAME (or a latent cache)")
    e.add_argument("--latents", default=None, help="cache name (default: the tokenizer folder's name)")
    e.add_argument("--holdout-percent", type=whole_number(0, 99), default=10, help="the training run's holdout_percent")
    e.add_argument("--batch", type=at_least_one, default=8, help="sequences per forward pass")
    e.add_argument("--out", required=True, type=output_folder, help="folder for metrics.json")
    e.set_defaults(func=_eval)


def _train(args: argparse.Namespace) -> int:
    import json

    from drivewm.ar.train import RECIPES, ar_train
    from drivewm.config import to_dict

    cfg = RECIPES.from_args(args, [f"train.device={args.device}"])
    print(json.dumps(to_dict(cfg), indent=2))
    if args.dry_run:
        return 0
    last = ar_train(cfg, args.data, args.tokenizer, args.out)
    print(json.dumps(last))
    print(f"model folder: {args.out}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    import json

    from drivewm.ar.evaluate import evaluate_folder

    metrics = evaluate_folder(args.model, args.data, args.latents, args.holdout_percent, args.batch, args.out)
    print(json.dumps(metrics))
    print(f"metrics: {args.out / 'metrics.json'}")
    return 0
