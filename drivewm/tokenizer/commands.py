"""``drivewm tokenizer train|encode|decode|eval`` (heavy imports inside the handlers; the recipe book is light)."""

from __future__ import annotations

import argparse
from pathlib import Path

from drivewm.choices import at_least_one, model_folder, output_folder, whole_number
from drivewm.tokenizer.recipe import RECIPES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tokenizer", help="video tokenizer: train, encode clips to a latent cache, decode, evaluate")
    tsub = p.add_subparsers(dest="tokenizer_command", metavar="ACTION", required=True)

    t = tsub.add_parser(
        "train",
        help="train (or resume) a tokenizer on clip shards",
        description="A preset is a size, a compression and a quantizer (--preset small --compression 8x8x8 "
        "--fsq); override any field with --set, e.g. --set train.steps=2000 --set data.crop=[96,160].",
    )
    RECIPES.add_arguments(t)
    t.add_argument("--data", required=True, type=Path, help="clip folder (shards)")
    t.add_argument("--out", required=True, type=output_folder, help="model folder; rerun with the same --out to resume")
    _threads(t)
    t.set_defaults(func=_train)

    e = tsub.add_parser("encode", help="write the latent cache CLIPDIR/latents/NAME/")
    e.add_argument("--model", required=True, type=model_folder, help="tokenizer model folder (or shipped:tokenizer)")
    e.add_argument("--data", required=True, type=Path, help="clip folder (shards)")
    e.add_argument("--name", default=None, help="cache name (default: the model folder's name)")
    _tiling(e)
    e.set_defaults(func=_encode)

    d = tsub.add_parser("decode", help="latent cache or clips -> mp4 per clip and camera")
    d.add_argument("--model", required=True, type=model_folder, help="tokenizer model folder (or shipped:tokenizer)")
    d.add_argument("--latents", type=Path, help="latent cache folder (CLIPDIR/latents/NAME)")
    d.add_argument("--data", type=Path, help="clip folder or tar to reconstruct (encode + decode)")
    d.add_argument("--key", action="append", default=None, help="only these clip keys (repeatable)")
    d.add_argument("--out", required=True, type=output_folder, help="folder for KEY.CAMERA.mp4")
    _tiling(d)
    d.set_defaults(func=_decode)

    v = tsub.add_parser("eval", help="PSNR, SSIM, temporal stability + side-by-side PNG")
    v.add_argument("--model", required=True, type=model_folder, help="tokenizer model folder (or shipped:tokenizer)")
    v.add_argument("--data", required=True, type=Path, help="clip folder (shards)")
    v.add_argument("--out", required=True, type=output_folder, help="folder for metrics.json and side_by_side.png")
    v.add_argument(
        "--split",
        choices=("all", "holdout", "train"),
        default="all",
        help="which clips: all, or those held out (or not) from training by key hash",
    )
    v.add_argument(
        "--holdout-percent", type=whole_number(0, 99), default=10, help="the training run's holdout_percent (0-99)"
    )
    v.add_argument("--max-clips", type=at_least_one, default=None, help="score N clips spread evenly over the input")
    v.add_argument("--max-views", type=at_least_one, default=None, help="score only the first N cameras of each clip")
    _threads(v)
    v.set_defaults(func=_eval)


def _threads(p: argparse.ArgumentParser) -> None:
    p.add_argument("--threads", type=whole_number(0), default=0, help="torch CPU threads (0: torch's default)")
    p.add_argument(
        "--device", default="auto", choices=["auto", "cpu", "cuda"], help="where to run (auto: CUDA when available)"
    )


def _tiling(p: argparse.ArgumentParser) -> None:
    p.add_argument("--chunk", type=int, default=None, help="latent frames per causal time chunk (default: one pass)")
    p.add_argument("--tile", type=int, default=None, help="spatial tile size in latent pixels (default: no tiling)")
    p.add_argument("--overlap", type=int, default=6, help="tile overlap in latent pixels")
    _threads(p)


def _set_threads(args: argparse.Namespace) -> None:
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)


def _tiling_config(args: argparse.Namespace):
    from drivewm.tokenizer.tiling import TilingConfig

    return TilingConfig(chunk_latent_frames=args.chunk, tile_latent=args.tile, overlap_latent=args.overlap)


def _train(args: argparse.Namespace) -> int:
    import json

    from drivewm.config import to_dict
    from drivewm.tokenizer.train import tokenizer_train

    _set_threads(args)
    cfg = RECIPES.from_args(args, [f"train.device={args.device}"])
    print(json.dumps(to_dict(cfg), indent=2))
    if args.dry_run:
        return 0
    last = tokenizer_train(cfg, args.data, args.out)
    print(json.dumps(last))
    print(f"model folder: {args.out}")
    return 0


def _encode(args: argparse.Namespace) -> int:
    from drivewm.tokenizer.latent_cache import encode_clips

    _set_threads(args)
    report = encode_clips(args.model, args.data, args.name, _tiling_config(args))
    for item in report["skipped"]:
        print(f"  skipped {item['key']}: {item['reason']}")
    kept = f" ({report['reused']} kept from the cache as they were)" if report["reused"] else ""
    print(f"encoded {report['encoded']} clips{kept}, skipped {len(report['skipped'])}; cache: {report['cache']}")
    return 0


def _decode(args: argparse.Namespace) -> int:
    from drivewm.errors import DrivewmError
    from drivewm.tokenizer.decode import decode_to_mp4

    if (args.latents is None) == (args.data is None):
        raise DrivewmError("tokenizer decode: give exactly one of --latents CACHEDIR or --data CLIPDIR")
    _set_threads(args)
    paths = decode_to_mp4(args.model, args.latents or args.data, args.out, args.key, _tiling_config(args))
    print(f"wrote {len(paths)} videos to {args.out}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    import json

    from drivewm.tokenizer.evaluate import evaluate_tokenizer

    _set_threads(args)
    metrics = evaluate_tokenizer(
        args.model, args.data, args.out, args.split, args.holdout_percent, args.max_clips, args.max_views
    )
    print(json.dumps({k: v for k, v in metrics.items() if k != "clips"}))
    print(f"metrics: {args.out / 'metrics.json'}")
    return 0
