"""Where do a clip's frame-to-frame matches lie: on the road, or on the far scenery and sky?

A rig-aware reconstruction can register every frame of a clip that stands still: the far scenery
fixes the rotation, and the rig's baselines carry the registration (docs/eval-protocol.md,
``pose_success_path``). What gives it translation is parallax, and in a driving camera most of that
is the road below the horizon. This prints, for clip folders (curated clips, ``drivewm generate``
output or anything ``drivewm eval`` reads), the front camera's SIFT matches between consecutive frames
(every other pair) that the eval's robust fundamental matrix verifies (its MAGSAC settings): how many
a pair keeps, the share that lies below the image's middle row (the rig's cameras look level, so that
is the horizon) and the median image motion of those below and above it.

    python studies/match_rows.py CLIPS_OR_SAMPLES [...] [--max-clips 6] [--camera CAM_FRONT]

Numbers: git show a88b7a4:docs/quality-vs-compute.md, "Pose success without motion".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from drivewm.clips.shards import spread
from drivewm.eval.config import EvalConfig
from drivewm.eval.epipolar import fit_fundamental
from drivewm.eval.inputs import load_items
from drivewm.eval.matching import FrameMatcher


def verified_matches(a: np.ndarray, b: np.ndarray, matcher: FrameMatcher, ids: tuple, cfg: EvalConfig):
    """(N, 2) pixel positions in frames ``a`` and ``b`` of the matches the eval's robust fundamental
    matrix verifies (drivewm.eval.epipolar.fit_fundamental, the protocol's settings); empty where it
    finds none."""
    m = matcher.match(ids[0], a, ids[1], b)
    F, inliers = fit_fundamental(m, cfg.epipolar)
    if F is None:
        return m.uv_a[:0], m.uv_b[:0]
    return m.uv_a[inliers], m.uv_b[inliers]


def match_rows(location: str, camera: str, max_clips: int | None) -> dict[str, float]:
    """Verified matches a frame pair, their share below the middle row, and the median motion (px)
    of those below and above it, over ``max_clips`` clips spread over the folder."""
    cfg = EvalConfig()
    per_pair, below_share, motion_below, motion_above = [], [], [], []
    for item in spread(load_items(Path(location), None), max_clips):
        frames = item.videos()[camera]
        matcher = FrameMatcher(cfg.match)
        for t in range(0, len(frames) - 1, 2):
            a, b = verified_matches(frames[t], frames[t + 1], matcher, (t, t + 1), cfg)
            if not len(a):
                continue
            below = a[:, 1] > frames.shape[1] / 2
            motion = np.linalg.norm(b - a, axis=1)
            per_pair.append(len(a))
            below_share.append(below.mean())
            motion_below += list(motion[below])
            motion_above += list(motion[~below])
    median = lambda v: float(np.median(v)) if v else float("nan")  # noqa: E731
    return {
        "verified_per_pair": float(np.mean(per_pair)) if per_pair else 0.0,
        "below_horizon": float(np.mean(below_share)) if below_share else float("nan"),
        "motion_below_px": median(motion_below),
        "motion_above_px": median(motion_above),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+")
    ap.add_argument("--max-clips", type=int, default=6, help="clips per folder, spread over it (default 6)")
    ap.add_argument("--camera", default="CAM_FRONT")
    args = ap.parse_args()
    print("| folder | verified matches a pair | below the horizon | motion below (px) | motion above (px) |")
    print("|---|---|---|---|---|")
    for folder in args.folders:
        r = match_rows(folder, args.camera, args.max_clips)
        print(
            f"| {folder} | {r['verified_per_pair']:.1f} | {r['below_horizon']:.2f} | "
            f"{r['motion_below_px']:.2f} | {r['motion_above_px']:.2f} |"
        )


if __name__ == "__main__":
    main()
