"""``drivewm view LOG.mcap [--out rec.rrd] [--topic-map MAP]``: a drive log as a Rerun recording.

The reader and Rerun are imported inside the handler, so that ``drivewm --help`` stays fast.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drivewm import resources


def register(subparsers) -> None:
    p = subparsers.add_parser("view", help="write a Rerun recording (.rrd) of a drive log", description=__doc__)
    p.add_argument("log", help="MCAP drive log, or a folder of split-bag .mcap files")
    p.add_argument("--out", default=None, help="output .rrd (default: next to the log, LOG.rrd)")
    p.add_argument(
        "--topic-map",
        default=None,
        help="topic map for fleet logs: a YAML path or a packaged name ("
        + ", ".join(resources.names("topicmaps"))
        + ")",
    )
    p.set_defaults(func=run_view)


def run_view(args: argparse.Namespace) -> int:
    from drivewm.logs.reader import read_log
    from drivewm.logs.viewer import write_recording

    log = read_log(args.log, topic_map=args.topic_map, require_images=False)
    out = Path(args.out) if args.out else Path(args.log).with_suffix(".rrd")
    write_recording(log, out)
    frames = sum(len(f) for f in log.images.values())
    print(
        f"{args.log}: {len(log.rig.cameras)} cameras, {frames} images, {len(log.pose_timestamps_ns)} poses, "
        f"{len(log.agents)} agent ticks -> {out} (open with: rerun {out})"
    )
    return 0
