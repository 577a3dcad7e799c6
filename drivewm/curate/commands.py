"""``drivewm curate`` and ``drivewm import-video``.

Thin: parse, build the config, print it, call the library; the curation stage (OpenCV, filterpy,
scenedetect) is imported inside the handlers so that ``drivewm --help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from drivewm.choices import add_registry_argument, at_least_one, output_folder
from drivewm.config import to_dict
from drivewm.curate.config import CURATE_RECIPES
from drivewm.curate.pool import start_fork_server
from drivewm.errors import BatchError, DrivewmError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("curate", help="drive logs -> synchronized, filtered, captioned multi-view clip shards")
    p.add_argument(
        "logs", nargs="+", type=Path, help="MCAP drive logs: files, folders of *.mcap, or split ROS 2 bag folders"
    )
    p.add_argument(
        "--out",
        required=True,
        type=output_folder,
        help="clip folder: shards, manifest.jsonl, report.json, contact_sheet.png",
    )
    CURATE_RECIPES.add_arguments(p)
    add_registry_argument(
        p, "--executor", "drivewm.curate.pipeline:EXECUTORS", "where logs run (default local)", default="local"
    )
    p.add_argument(
        "--workers",
        type=at_least_one,
        default=1,
        help="parallel logs (local processes, or Ray CPUs when starting Ray locally)",
    )
    p.add_argument("--ray-address", default=None, help="connect to a Ray cluster instead of starting one")
    p.set_defaults(func=_curate)

    v = sub.add_parser("import-video", help="a folder of mp4 files + a one-camera calibration YAML -> drive logs")
    v.add_argument("videos", nargs="+", type=Path, help="mp4 files or folders of them")
    v.add_argument("--calibration", required=True, help="rig YAML with one camera (its size is the stored image size)")
    v.add_argument("--out", required=True, type=output_folder, help="folder for the NAME.mcap logs")
    v.add_argument(
        "--tag",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="scene tag, e.g. weather=rain (default: unknown)",
    )
    v.set_defaults(func=_import_video)


def _expand(paths: list[Path]) -> list[Path]:
    """Logs from the arguments: files as given; a folder is a split ROS 2 bag (one log) when it has
    rosbag2's metadata.yaml, else a folder of logs (its *.mcap files)."""
    out: list[Path] = []
    for p in paths:
        out += sorted(p.glob("*.mcap")) if p.is_dir() and not (p / "metadata.yaml").is_file() else [p]
    return out


def _curate(args: argparse.Namespace) -> int:
    if args.executor == "local" and args.workers > 1 and not args.dry_run:
        start_fork_server()  # the pool's workers' imports, on another core while this process imports the stage
    from drivewm.curate import curate

    cfg = CURATE_RECIPES.from_args(args)
    print(json.dumps(to_dict(cfg)))
    if args.dry_run:
        return 0
    report = curate(
        _expand(args.logs), args.out, cfg, executor=args.executor, workers=args.workers, ray_address=args.ray_address
    )
    print(
        f"kept {report['kept']} clips, dropped {report['dropped']}; "
        f"logs ok {report['logs_ok']}, failed {report['logs_failed']}; report: {args.out / 'report.json'}"
    )
    failed = [f"{name}: {log['error']}" for name, log in report["logs"].items() if log["status"] == "failed"]
    if not report["kept"]:
        lines = [f"{name}: {_why_nothing(log)}" for name, log in report["logs"].items()]
        raise BatchError(f"curate: no clip kept from {len(report['logs'])} log(s)", lines)
    for line in report["warnings"] + failed:
        print(f"warning: {line}", file=sys.stderr)
    for name, log in report["logs"].items():
        for warning in log.get("warnings", []):
            print(f"warning: {name}: {warning}", file=sys.stderr)
    return 0


def _why_nothing(log: dict) -> str:
    """Why a log of report.json gave no clip: its error, or what the filters dropped."""
    return log["error"] if log["status"] == "failed" else f"no clip kept (dropped {log['dropped']})"


def _import_video(args: argparse.Namespace) -> int:
    from drivewm.curate.import_video import import_videos

    tags = {}
    for t in args.tag:
        if "=" not in t:
            raise DrivewmError(f"--tag {t!r}: expected KEY=VALUE")
        k, val = t.split("=", 1)
        tags[k] = val
    report = import_videos(args.videos, args.calibration, args.out, tags)
    for path in report.logs:
        print(path)
    for line in report.warnings + [f"skipped {reason}" for reason in report.failed]:
        print(f"warning: {line}", file=sys.stderr)
    return 0
