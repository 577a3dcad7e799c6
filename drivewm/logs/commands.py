"""``drivewm view LOG.mcap [--out rec.rrd] [--topic-map MAP]``: a drive log as a Rerun recording.

The reader and Rerun are imported inside the handler, so that ``drivewm --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from drivewm import resources
from drivewm.choices import output_file


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "view",
        help="write a Rerun recording (.rrd) of a drive log",
        description="A drive log as a Rerun recording: cameras on the ego, images, trajectory, agent boxes.",
    )
    p.add_argument("log", help="MCAP drive log, or a folder of split-bag .mcap files")
    p.add_argument("--out", default=None, type=output_file, help="output .rrd (default: next to the log, LOG.rrd)")
    p.add_argument(
        "--topic-map",
        default=None,
        help="topic map for fleet logs: a YAML path or a packaged name ("
        + ", ".join(resources.names("topicmaps"))
        + ")",
    )
    p.set_defaults(func=run_view)


def run_view(args: argparse.Namespace) -> int:
    from drivewm.logs.reader import LogStream
    from drivewm.logs.viewer import write_recording

    out = args.out or Path(args.log).with_suffix(".rrd")
    n, warnings = write_recording(LogStream(args.log, topic_map=args.topic_map), out)
    for line in warnings:
        print(f"warning: {line}", file=sys.stderr)
    print(
        f"{args.log}: {n['cameras']} cameras, {n['image']} images, {n['poses']} poses, "
        f"{n['agents']} agent ticks -> {out} (open with: rerun {out})"
    )
    return 0
