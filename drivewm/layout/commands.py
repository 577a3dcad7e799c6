"""``drivewm layout CLIPS --out DIR``: each clip's layout as per-camera scenario-map videos and a contact sheet.

The renderer is imported inside the handler, so ``drivewm --help`` stays fast.
"""

from __future__ import annotations

import argparse

from drivewm.choices import at_least_one, output_folder


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "layout",
        help="render clips' layouts (road, lanes, boxes) into their cameras as videos and a contact sheet",
        description="Each clip's layout drawn into every camera of its rig (or --rig): OUT/KEY.CAMERA.mp4 per "
        "camera and OUT/contact_sheet.png, the clips' frames beside their layout.",
    )
    p.add_argument("clips", nargs="+", help="clip folders or shards (.tar)")
    p.add_argument("--out", required=True, type=output_folder, help="output folder")
    p.add_argument("--rig", default=None, help="render for this rig (name or YAML) instead of each clip's own")
    p.add_argument("--max-clips", type=at_least_one, default=None, help="render N clips spread evenly over the input")
    p.add_argument("--sheet-clips", type=at_least_one, default=4, help="clips on the contact sheet (default 4)")
    p.set_defaults(func=run_layout)


def run_layout(args: argparse.Namespace) -> int:
    from drivewm.geometry import load_rig
    from drivewm.layout.videos import write_layout_videos

    rig = load_rig(args.rig) if args.rig else None
    result = write_layout_videos(args.clips, args.out, rig, args.max_clips, args.sheet_clips)
    print(
        f"layout: {result.clips} clip(s), {len(result.videos)} video(s) -> {args.out}"
        + (f"; contact sheet {result.sheet}" if result.sheet else "")
    )
    return 0
