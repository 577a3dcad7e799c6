"""How wide a corridor should the reprojection's warp assume, and does it let a reconstruction travel?

``drivewm.multiview.warp`` renders a clip's first frame along a trajectory with a flat world: the
road plane, and everything above it at infinity. What stands beside the road then never comes
nearer, and structure from motion reconstructs such a clip standing still. ``--reproject-walls M``
puts vertical planes M metres left and right of the first ego frame. This study warps real clips'
first frames along their own logged waypoints, for each corridor width, and prints the PSNR of the
warped later frames against the true ones (over the pixels the warp renders). With ``--out DIR`` it
also writes the clips themselves (``DIR/real``) and each width's warps (``DIR/walls_W``) as
generated samples, for ``drivewm eval DIR/... --metrics tse,pose,traj`` (pose success, the path
ratio and TFE against the same waypoints).

    python studies/warp_walls.py CLIPS [--walls 0,6,10,15,25,40] [--keys K1,K2,...] [--max-clips 8] [--out DIR]

Numbers: git show a88b7a4:docs/quality-vs-compute.md, "The flat-world warp stands still".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from drivewm.clips.shards import spread
from drivewm.eval.inputs import load_items
from drivewm.multiview.reproject import reproject_first_frame_mask
from drivewm.multiview.writer import GeneratedSample, write_samples


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("clips", help="curated clips with ego poses (a folder of shards)")
    ap.add_argument("--walls", default="0,6,10,15,25,40", help="corridor widths, m (0: the flat world)")
    ap.add_argument("--keys", default="", help="comma-separated clip key endings (default: --max-clips spread)")
    ap.add_argument("--max-clips", type=int, default=8)
    ap.add_argument("--out", type=Path, help="write the clips and their warps as generated samples for drivewm eval")
    args = ap.parse_args()
    widths = [float(x) for x in args.walls.split(",")]
    items = load_items(Path(args.clips), None)
    if args.keys:
        items = [next(i for i in items if i.key.endswith(k)) for k in args.keys.split(",")]
    else:
        items = spread(items, args.max_clips)
    psnr = {wm: [] for wm in widths}
    written = {name: [] for name in ["real", *(f"walls_{wm:g}" for wm in widths)]}
    for item in items:
        vids = item.videos()
        videos = np.stack([vids[c.name] for c in item.rig.cameras])
        wp = np.asarray(item.trajectory_ego, dtype=np.float64)

        def sample(v: np.ndarray, item=item, wp=wp) -> GeneratedSample:
            return GeneratedSample(v, item.rig, item.key, [item.key] * len(v), wp, item.trajectory_dt_s, {})

        written["real"].append(sample(videos))
        row = f"{item.key[-44:]:44s}"
        for wm in widths:
            out, valid = reproject_first_frame_mask(videos, item.rig, wp, item.trajectory_dt_s, item.fps, walls_m=wm)
            m = valid[:, 1:]
            mse = ((out[:, 1:].astype(np.float64) - videos[:, 1:])[m] ** 2).mean()
            psnr[wm].append(10 * np.log10(255**2 / mse))
            written[f"walls_{wm:g}"].append(sample(out))
            row += f"  {wm:g} m: {psnr[wm][-1]:.2f}"
        print(row, flush=True)
    for wm in widths:
        print(
            f"walls {wm:g} m: mean PSNR of the warped later frames {np.mean(psnr[wm]):.2f} dB over {len(items)} clips"
        )
    if args.out:
        for name, samples in written.items():
            write_samples(args.out / name, samples, items[0].fps)
        print(
            f"samples in {args.out}/real and {args.out}/walls_*: score each with `drivewm eval DIR --metrics pose,traj`"
        )


if __name__ == "__main__":
    main()
