"""``drivewm eval LOCATION --rig R --out DIR``: the geometric-consistency benchmark (docs/DESIGN.md section 8).

Thin: parse, build the config, print it, call the library; the benchmark (OpenCV, pycolmap,
matplotlib) is imported inside the handler so that ``drivewm --help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
import sys

from drivewm import resources
from drivewm.choices import at_least_one, output_folder
from drivewm.config import to_dict
from drivewm.errors import BatchError
from drivewm.eval.config import ALL_METRICS, EVAL_RECIPES


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "eval",
        help="score clips or generated videos: TSE, CSE, pose success, ATE/RPE/TFE, adherence",
        description="Score clip shards, a folder of per-camera mp4, or one grid mp4.",
    )
    p.add_argument(
        "location", help="clip shard folder or .tar, a folder of CAMERA.mp4 (or of such folders), or a grid .mp4"
    )
    p.add_argument("--rig", default=None, help="rig name or YAML (required for mp4 inputs; overrides a clip's own rig)")
    p.add_argument(
        "--out",
        required=True,
        type=output_folder,
        help="output folder: metrics.json, metrics.md, error_distributions.png, eval.rrd",
    )
    p.add_argument("--workers", type=at_least_one, default=1, help="clips scored in parallel (processes)")
    p.add_argument(
        "--threads",
        type=at_least_one,
        default=None,
        help="threads per clip for its features and matches (default: the cores over the clips scored at once; "
        "the figures do not depend on it)",
    )
    p.add_argument("--metrics", default=None, help=f"comma list of {','.join(ALL_METRICS)} (default: the recipe's)")
    p.add_argument(
        "--reference",
        default=None,
        help="reference metrics shown beside the results: a JSON path or a packaged name ("
        + ", ".join(resources.names("references", ".json"))
        + ")",
    )
    EVAL_RECIPES.add_arguments(p)
    p.add_argument(
        "--rig-fit",
        default="same",
        choices=("same", "stretch", "crop"),
        help="videos of another aspect ratio than the rig: were they stretched or centre-cropped from it? "
        "(default: refuse them)",
    )
    p.add_argument("--grid", default=None, help="ROWSxCOLS of views in a single mp4, e.g. 2x3")
    p.add_argument("--cameras", default=None, help="comma list naming the grid cells row by row ('-' skips a cell)")
    p.add_argument("--no-pictures", action="store_true", help="skip the plots and the Rerun recording")
    p.add_argument("--max-clips", type=at_least_one, default=None, help="score N clips spread evenly over the input")
    p.set_defaults(func=run_eval)


def run_eval(args: argparse.Namespace) -> int:
    from drivewm.atomic import strict_json
    from drivewm.eval.suite import evaluate

    if args.metrics:
        args.overrides.append(f"metrics=[{args.metrics}]")
    cfg = EVAL_RECIPES.from_args(args)
    print(json.dumps(to_dict(cfg)))
    if args.dry_run:
        return 0
    cameras = args.cameras.split(",") if args.cameras else None
    metrics = evaluate(
        args.location,
        args.rig,
        args.out,
        cfg,
        workers=args.workers,
        grid=args.grid,
        cameras=cameras,
        reference=args.reference,
        pictures=not args.no_pictures,
        rig_fit=args.rig_fit,
        max_clips=args.max_clips,
        threads=args.threads,
    )
    # The same values as metrics.json's top level, as strict JSON (NaN -> null), so a script can parse stdout.
    summary = strict_json({k: v for k, v in metrics.items() if k not in ("clips", "config")})
    print(json.dumps(summary, indent=2, allow_nan=False))
    print(f"wrote {args.out}/metrics.json and metrics.md")
    failed = [m["error"] for m in metrics["clips"].values() if "error" in m]
    if len(failed) == metrics["num_clips"]:
        raise BatchError(f"eval: every input failed ({len(failed)} of {metrics['num_clips']})", failed)
    for line in failed:
        print(f"warning: failed {line}", file=sys.stderr)
    for key, m in metrics["clips"].items():
        for line in m.get("warnings", []):
            print(f"warning: {key}: {line}", file=sys.stderr)
    return 0
