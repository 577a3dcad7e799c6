"""``drivewm transfer`` and ``drivewm transfer-train`` (thin: parse, build config, print it, call the library)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from drivewm.choices import at_least_one, model_folder, output_folder, seed

WEATHERS = ["clear", "overcast", "rain", "snow", "fog"]  # drivewm.logs.types.WEATHERS (not imported: --help stays fast)
TIMES_OF_DAY = ["day", "dusk", "night"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("transfer", help="the same clips in another weather / time of day (labels kept)")
    p.add_argument("clips", nargs="+", type=Path, help="clip shards (.tar) or clip folders")
    p.add_argument(
        "--model",
        type=model_folder,
        help="transfer model folder, shipped:transfer (the default), or a Text2World folder (the SDEdit baseline)",
    )
    p.add_argument("--to", required=True, choices=WEATHERS, dest="weather", help="target weather")
    p.add_argument("--time-of-day", choices=TIMES_OF_DAY, help="target time of day (default: each clip's own)")
    p.add_argument(
        "--out", required=True, type=output_folder, help="output folder: clip shards, sheets/, contact_sheet.png"
    )
    p.add_argument("--steps", type=int, default=8, help="sampler steps (default 8)")
    p.add_argument("--guidance", type=float, default=1.0, help="guidance on the target condition (1 = none)")
    p.add_argument("--sampler", default="euler", choices=["euler", "heun"])
    p.add_argument("--seed", type=seed, default=0, help="view v draws its noise from seed + v")
    p.add_argument(
        "--start-sigma",
        type=float,
        default=None,
        help="start from the source noised to this sigma (transfer model: optional; Text2World/SDEdit: required)",
    )
    p.add_argument(
        "--tokenizer", type=model_folder, help="tokenizer folder or shipped:tokenizer (default: the model's)"
    )
    p.add_argument(
        "--device", default="auto", choices=["auto", "cpu", "cuda"], help="where to run (auto: CUDA when available)"
    )
    p.add_argument("--max-clips", type=at_least_one, default=None, help="transfer only the first N clips (a preview)")
    p.add_argument(
        "--no-detail",
        action="store_true",
        help="write the decoded transfer as it is (default: add back the source detail the tokenizer drops)",
    )
    p.add_argument(
        "--detail-band",
        type=float,
        default=None,
        help="model pixels: the source's structure finer than a Gaussian of this sigma replaces the transfer's, "
        "which keeps the colour, light and haze (default 8, one tokenizer cell; 0: only the detail the "
        "tokenizer drops)",
    )
    p.add_argument(
        "--no-shared-look",
        action="store_true",
        help="restore detail in each view on its own (default: the transfer's light, colour, haze and contrast "
        "are shared between cameras where they overlap; the source's structure stays each view's own)",
    )
    p.add_argument(
        "--model-resolution",
        action="store_true",
        help="write clips at the model's image size, the rig scaled to it (default: the source's size and rig "
        "when larger; the model still works at its size and the detail above it comes from the source)",
    )
    p.set_defaults(func=transfer_command, lock_out="transfer")

    t = sub.add_parser("transfer-train", help="post-train a transfer model from a Text2World model on paired clips")
    t.add_argument(
        "--init",
        required=True,
        type=model_folder,
        help="Text2World model folder (or shipped:text2world) to start from, or a transfer folder to fine-tune",
    )
    t.add_argument("--data", required=True, type=Path, help="paired clip folder holding latents/NAME (or the cache)")
    t.add_argument(
        "--out", required=True, type=output_folder, help="model folder to write (resumes if it holds train_state.pt)"
    )
    # the flags of drivewm.recipe.RecipeBook.add_arguments, spelled out: importing the book's presets
    # (drivewm.transfer.train) would pull in torch for `drivewm --help`
    t.add_argument("--preset", help="debug | small | base (default: the recipe's, else debug)")
    t.add_argument("--recipe", type=Path, help="recipe YAML (keys: preset, config, overrides)")
    t.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help="override a field")
    t.add_argument("--dry-run", action="store_true", help="print the resolved config and exit")
    t.add_argument(
        "--device", choices=["auto", "cpu", "cuda"], help="where to train (sets train.device; default: the recipe's)"
    )
    t.set_defaults(func=transfer_train_command)


def transfer_command(args: argparse.Namespace) -> int:
    from drivewm.generate.config import SamplingConfig
    from drivewm.transfer.apply import TransferOptions, transfer_clips

    options = TransferOptions(
        args.weather,
        args.time_of_day,
        SamplingConfig(args.steps, args.sampler, args.guidance, seed=args.seed),
        args.start_sigma,
        args.tokenizer,
        args.device,
        args.max_clips,
        detail=not args.no_detail,
        **({} if args.detail_band is None else {"detail_band": args.detail_band}),
        shared_look=not args.no_shared_look,
        model_resolution=args.model_resolution,
    )
    if args.model is None:
        from drivewm.model_folders import shipped_model

        args.model = shipped_model("transfer")
    report = transfer_clips(args.model, args.clips, options, args.out)
    for item in report["failed"]:
        print(f"skipped {item.get('clip', item['shard'])}: {item['error']}")
    print(f"wrote {len(report['written'])} transferred clip(s) to {args.out} ({len(report['failed'])} skipped)")
    return 0


def transfer_train_command(args: argparse.Namespace) -> int:
    from drivewm.config import to_dict
    from drivewm.transfer.train import RECIPES, train_transfer

    device = [f"train.device={args.device}"] if args.device else []
    cfg = RECIPES.resolve(args.preset, args.recipe, [*args.overrides, *device])
    print(json.dumps(to_dict(cfg), indent=2))
    if args.dry_run:
        return 0
    last = train_transfer(cfg, args.init, args.data, args.out)
    print(f"wrote {args.out} ({json.dumps(last)})")
    return 0
