"""``drivewm eval LOCATION --rig R --out DIR``: the geometric-consistency benchmark (DESIGN.md section 8)."""

from __future__ import annotations

import argparse


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
        "--out", required=True, help="output folder: metrics.json, metrics.md, error_distributions.png, eval.rrd"
    )
    p.add_argument("--workers", type=int, default=1, help="clips scored in parallel (processes)")
    p.add_argument("--metrics", default=None, help="comma list of tse,cse,pose,traj,adherence (default: the suite's)")
    p.add_argument(
        "--reference", default=None, help="reference metrics JSON shown beside the results (eval/reference/*.json)"
    )
    p.add_argument("--suite", default=None, help="suite YAML overriding protocol constants (eval/suites/*.yaml)")
    p.add_argument("--grid", default=None, help="ROWSxCOLS of views in a single mp4, e.g. 2x3")
    p.add_argument("--cameras", default=None, help="comma list naming the grid cells row by row ('-' skips a cell)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a protocol constant, e.g. match.ratio=0.75",
    )
    p.add_argument("--no-pictures", action="store_true", help="skip the plots and the Rerun recording")
    p.set_defaults(func=run_eval)


def run_eval(args: argparse.Namespace) -> int:
    import json
    import sys

    from drivewm.config import apply_overrides, load_yaml
    from drivewm.errors import BatchError
    from drivewm.eval.config import EvalConfig
    from drivewm.eval.suite import evaluate

    base = load_yaml(args.suite) if args.suite else {}
    overrides = list(args.set) + ([f"metrics=[{args.metrics}]"] if args.metrics else [])
    cfg = apply_overrides(EvalConfig, base, overrides, where=args.suite or "eval config")
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
    )
    summary = {k: v for k, v in metrics.items() if k not in ("clips", "config")}
    print(json.dumps(summary, indent=2, default=str))
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
