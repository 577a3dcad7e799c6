"""``drivewm eval LOCATION --rig R --out DIR``: the geometric-consistency benchmark (docs/DESIGN.md section 8).

Two more actions share the command: ``drivewm eval distribution GENERATED --real REAL --inception F
--i3d F --out DIR`` (FID / FVD, drivewm.eval.distribution) and ``drivewm eval compare RUN_A RUN_B ...
--out DIR`` (a leaderboard of eval outputs, drivewm.eval.compare). A LOCATION literally named
``compare`` or ``distribution`` is given as ``./compare``.

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
from drivewm.errors import BatchError, DrivewmError
from drivewm.eval.config import ALL_METRICS, EVAL_RECIPES


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "eval",
        help="score clips or generated videos: TSE, CSE, pose success, ATE/RPE/TFE, adherence",
        description="Score clip shards, a folder of per-camera mp4, or one grid video (mp4, gif, png...).",
    )
    p.add_argument(
        "location",
        nargs="+",
        metavar="LOCATION",
        help="clip shards (.tar or folder), a folder of CAMERA.mp4 (or of such folders), a grid video (mp4, gif, png); "
        "'distribution GENERATED' (FID/FVD); 'compare EVALDIR ...'",
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
    p.add_argument("--grid", default=None, help="ROWSxCOLS of views in a single video or image, e.g. 2x3")
    p.add_argument("--cameras", default=None, help="comma list naming the grid cells row by row ('-' skips a cell)")
    p.add_argument("--crop", type=_crop, metavar="X,Y,W,H", help="pixel box of each frame holding the view(s)")
    p.add_argument("--frames", type=_frames, metavar="START:END", help="the frames scored (END exclusive)")
    p.add_argument("--grid-border", type=int, default=0, metavar="PX", help="pixels cut from each grid cell edge")
    p.add_argument("--real", metavar="DIR", help="distribution: the real clips (shards or mp4 folder)")
    p.add_argument("--inception", metavar="FILE", help="distribution: local TorchScript Inception (FID)")
    p.add_argument("--i3d", metavar="FILE", help="distribution: local TorchScript I3D (FVD)")
    p.add_argument("--bootstrap", type=int, default=50, metavar="N", help="distribution: resamples per interval")
    p.add_argument("--fvd-frames", type=at_least_one, default=16, metavar="N", help="distribution: frames per FVD clip")
    p.add_argument("--no-pictures", action="store_true", help="skip the plots and the Rerun recording")
    p.add_argument("--max-clips", type=at_least_one, default=None, help="score N clips spread evenly over the input")
    p.set_defaults(func=run_eval)


def _crop(text: str) -> tuple[int, int, int, int]:
    from drivewm.eval.framing import parse_crop

    try:
        return parse_crop(text)
    except DrivewmError as exc:  # argparse turns this into the CLI's one-line error, exit 2
        raise argparse.ArgumentTypeError(str(exc)) from None


def _frames(text: str) -> tuple[int, int | None]:
    from drivewm.eval.framing import parse_frames

    try:
        return parse_frames(text)
    except DrivewmError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _framing(args: argparse.Namespace):
    from drivewm.eval.framing import Framing

    start, end = args.frames or (0, None)
    return Framing(args.crop, start, end, args.grid_border)


def run_eval(args: argparse.Namespace) -> int:
    head, rest = args.location[0], args.location[1:]
    if head == "compare":
        return run_compare(rest, args)
    if head == "distribution":
        return run_distribution(rest, args)
    if rest:
        raise DrivewmError(f"eval: one LOCATION, got {args.location} (or: eval compare RUN..., eval distribution GEN)")
    return run_score(head, args)


def run_score(location: str, args: argparse.Namespace) -> int:
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
        location,
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
        framing=_framing(args),
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


def run_distribution(rest: list[str], args: argparse.Namespace) -> int:
    """``eval distribution GENERATED --real REAL``: FID / FVD per view and over all views."""
    from drivewm.eval.distribution import DistributionConfig, distribution_metrics, markdown, write_distribution
    from drivewm.eval.inputs import load_items

    if len(rest) != 1 or args.real is None:
        raise DrivewmError("eval distribution: give one GENERATED location and --real REAL")
    cameras = args.cameras.split(",") if args.cameras else None
    generated = load_items(rest[0], args.rig, args.grid, cameras, args.rig_fit, _framing(args))
    real = load_items(args.real, args.rig, None, None, args.rig_fit)
    cfg = DistributionConfig(fvd_frames=args.fvd_frames, bootstrap=args.bootstrap)
    metrics = distribution_metrics(generated, real, args.inception, args.i3d, cfg)
    metrics["generated"], metrics["real"] = rest[0], args.real
    write_distribution(args.out, metrics)
    print(markdown(metrics))
    print(f"wrote {args.out}/distribution.json and distribution.md")
    return 0


def run_compare(runs: list[str], args: argparse.Namespace) -> int:
    """``eval compare RUN_A RUN_B ...``: eval outputs side by side (compare.html)."""
    from drivewm.eval.compare import compare_runs

    page = compare_runs(runs, args.out, pictures=not args.no_pictures)
    print(f"wrote {page}")
    return 0
