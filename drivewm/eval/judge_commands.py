"""``drivewm judge train|eval|score``: the layout judge (thin: parse, build config, print it, call the library)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from drivewm.choices import model_folder, output_folder, whole_number

DEVICES = ["auto", "cpu", "cuda"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("judge", help="the layout judge: train it, evaluate it, score generated clips against truth")
    jsub = p.add_subparsers(dest="judge_command", metavar="ACTION", required=True)

    t = jsub.add_parser("train", help="train a judge on labelled simulated clips (drivewm simulate --labels)")
    t.add_argument("--data", required=True, type=Path, action="append", help="labelled clip folder (repeatable)")
    t.add_argument("--out", required=True, type=output_folder, help="model folder (resumes if it holds train_state.pt)")
    # drivewm.recipe.RecipeBook.add_arguments' flags, spelled out: the book (drivewm.eval.judge_train) imports torch
    t.add_argument("--preset", help="cpu | debug (default: the recipe's, else cpu)")
    t.add_argument("--recipe", type=Path, help="recipe YAML (keys: preset, config, overrides)")
    t.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help="override a field")
    t.add_argument("--dry-run", action="store_true", help="print the resolved config and exit")
    t.add_argument("--device", choices=DEVICES, help="where to train (sets train.device)")
    t.set_defaults(func=train_command, lock_out="judge-train")

    e = jsub.add_parser("eval", help="per-class IoU and mIoU of a judge on labelled clips")
    e.add_argument("--model", type=model_folder, default="shipped:judge", help="judge folder (default shipped:judge)")
    e.add_argument("--data", required=True, type=Path, action="append", help="labelled clip folder (repeatable)")
    e.add_argument("--frame-stride", type=whole_number(1), default=4, help="judge every n-th frame (default 4)")
    e.add_argument("--out", type=output_folder, help="folder for judge_eval.json (default: print only)")
    e.add_argument("--device", choices=DEVICES, default="auto")
    e.set_defaults(func=eval_command)

    s = jsub.add_parser("score", help="generated clips against the simulator's truth: PSNR, SSIM, judge mIoU")
    s.add_argument("generated", type=Path, help="generated clip folder (clips keep their source's pair_id)")
    s.add_argument("--truth", required=True, type=Path, help="the simulator's clips of the same drives, all conditions")
    s.add_argument("--model", type=model_folder, default="shipped:judge", help="judge folder (default shipped:judge)")
    s.add_argument("--out", required=True, type=output_folder, help="folder for scores.json and contact_sheet.png")
    s.add_argument("--frame-stride", type=whole_number(1), default=1, help="judge every n-th frame (default 1)")
    s.add_argument("--sheet-clips", type=whole_number(0), default=6, help="pairs on the contact sheet (default 6)")
    s.add_argument("--device", choices=DEVICES, default="auto")
    s.set_defaults(func=score_command, lock_out="judge-score")


def train_command(args: argparse.Namespace) -> int:
    from drivewm.config import to_dict
    from drivewm.eval.judge_train import RECIPES, train_judge

    device = [f"train.device={args.device}"] if args.device else []
    cfg = RECIPES.resolve(args.preset, args.recipe, [*args.overrides, *device])
    print(json.dumps(to_dict(cfg), indent=2))
    if args.dry_run:
        return 0
    last = train_judge(cfg, args.data, args.out)
    print(f"wrote {args.out} ({json.dumps(last)})")
    return 0


def eval_command(args: argparse.Namespace) -> int:
    from drivewm.atomic import write_json
    from drivewm.device import resolve_device
    from drivewm.eval.judge import Judge
    from drivewm.eval.judge_train import evaluate_judge, load_labelled

    judge = Judge.from_pretrained(args.model).to(resolve_device(args.device))
    report = {"model": str(args.model), "data": [str(p) for p in args.data], "frame_stride": args.frame_stride}
    report |= evaluate_judge(judge, load_labelled(args.data, args.frame_stride))
    for name, iou in report["iou"].items():
        print(f"{name:12s} IoU {iou:.3f}")
    print(f"mIoU {report['miou']:.3f}, pixel accuracy {report['pixel_accuracy']:.3f} on {report['frames']} frames")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        write_json(args.out / "judge_eval.json", report)
    return 0


def score_command(args: argparse.Namespace) -> int:
    from drivewm.eval.truth import ScoreOptions, score_against_truth

    options = ScoreOptions(args.frame_stride, args.sheet_clips, args.device)
    scores = score_against_truth(args.generated, args.truth, args.model, args.out, options)
    for name, row in {**scores["by_condition"], "all": scores["overall"]}.items():
        print(
            f"{name:12s} {row['clips']:3d} clips  PSNR {row['psnr']:.2f} dB  SSIM {row['ssim']:.3f}  "
            f"judge mIoU {row['miou_generated']:.3f} generated / {row['miou_truth']:.3f} true "
            f"= {row['miou_ratio']:.2f}"
        )
    for item in scores["unpaired"]:
        print(f"unpaired {item['clip']}: {item['reason']}")
    print(f"wrote {args.out / 'scores.json'} and {args.out / 'contact_sheet.png'}")
    return 0
