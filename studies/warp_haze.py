"""Does the reprojection carry fog's airlight toward the camera, and what takes it back out?

`--reproject` warps the first frame of every camera along the trajectory (drivewm.multiview.warp):
the road at frame t is looked up where the first frame saw it, further away. In fog that far road
is mostly airlight, so the warped road brightens frame by frame: on a held-out straight fog drive
the true frames' ground stays at one luma while the warp of its own first frame climbs by tens of
levels, and a generated fog sample refined from 0.1 reads snow.

Two corrections, both from the first frame alone (as a generated sample gives it) and both using
the distances the warp knows (the road plane; points at infinity are left):

- ``profile`` (default; drivewm.views.reshade, the ``reshade`` post-step): the first frames give
  the median colour of the road within 3 m of the ego's line against distance, mu(d); a road pixel
  of frame t at distance d_t, fetched from d_0, gets ``I + mu(d_t) - mu(d_0)``. Model-free: haze, a
  wet road's grazing-angle sheen, whatever makes the far road look unlike the near one, and the
  identity where the road looks alike at every distance.
- ``koschmieder``: ``I = A + (J - A) exp(-beta d)`` (Koschmieder's law), so seen from d_t instead of
  d_0 a point shows ``A + (I_0 - A) exp(beta (d_0 - d_t))``; the airlight A is read near the
  horizon and beta from a line fitted to log |A - road luma| against distance.

For each clip this prints the fitted beta, the ground luma (bottom third) of the true first and
last frames, of the warp and of the corrected warp, and the PSNR of the warped later frames
against the true ones over the pixels the warp renders; then the mean PSNR per weather.

    python studies/warp_haze.py HELDOUT_CLIPS [--weathers fog,clear,snow,rain] [--per-weather 3]
        [--method profile|koschmieder]

Numbers: studies/README.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from drivewm.eval.inputs import load_items
from drivewm.geometry import invert_T, pixel_rays
from drivewm.multiview.trajectories import poses_from_waypoints
from drivewm.views.reproject import reproject_first_frame
from drivewm.views.reshade import PROFILE_M, reshade, surface_distances

LUMA = np.array([0.299, 0.587, 0.114])
HORIZON_DEG = (0.0, 3.0)  # rays this far above the horizon, at infinity, give the airlight


def fit_haze(first: np.ndarray, rig, d0_first: np.ndarray) -> tuple[np.ndarray, float]:
    """Airlight (RGB, 0-255) and extinction beta (1/m) from the first frames uint8 (V, H, W, 3) and their
    surfaces' distances (V, H, W), inf at infinity."""
    v_count, h, w = d0_first.shape
    uv = np.stack(np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5), -1).reshape(-1, 2)
    sky = []
    for v, cam in enumerate(rig.cameras):
        rays = pixel_rays(cam.K * np.array([[w / cam.width], [h / cam.height], [1]]), uv) @ cam.T_ego_from_cam[:3, :3].T
        elev = np.degrees(np.arctan2(rays[:, 2], np.linalg.norm(rays[:, :2], axis=1))).reshape(h, w)
        band = (elev >= HORIZON_DEG[0]) & (elev <= HORIZON_DEG[1]) & ~np.isfinite(d0_first[v])
        sky.append(first[v][band])
    sky = np.concatenate(sky).astype(np.float64)
    airlight = np.median(sky, axis=0) if len(sky) else np.full(3, 255.0)
    a_luma = float(airlight @ LUMA)
    road = np.isfinite(d0_first) & (d0_first >= PROFILE_M[0]) & (d0_first <= PROFILE_M[1])
    dist, luma = d0_first[road], first[road].astype(np.float64) @ LUMA
    if len(dist) < 50:
        return airlight, 0.0
    edges = np.quantile(dist, np.linspace(0, 1, 13))
    xs, ys = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (dist >= lo) & (dist < hi)
        if m.sum() >= 10:
            xs.append(np.median(dist[m]))
            ys.append(np.log(max(abs(a_luma - np.median(luma[m])), 1.0)))
    slope = np.polyfit(xs, ys, 1)[0] if len(xs) >= 3 else 0.0
    return airlight, max(-float(slope), 0.0)


def rehaze(warped: np.ndarray, valid: np.ndarray, d_t, d_0, airlight, beta) -> np.ndarray:
    """The warp as seen from each frame's own distance: ``A + (I - A) exp(beta (d_0 - d_t))``."""
    finite = np.isfinite(d_t) & np.isfinite(d_0)
    delta = np.where(finite, np.where(finite, d_0, 0.0) - np.where(finite, d_t, 0.0), 0.0)
    gain = np.exp(np.clip(beta * delta, -10, 10))[..., None]
    out = airlight + (warped.astype(np.float64) - airlight) * gain
    out = np.where(valid[..., None], out, warped)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def ground_luma(v: np.ndarray) -> np.ndarray:
    luma = v.astype(np.float64) @ LUMA
    return luma[:, :, 2 * luma.shape[2] // 3 :].mean(axis=(0, 2, 3))


def psnr_valid(a: np.ndarray, b: np.ndarray, valid: np.ndarray) -> float:
    mse = ((a[:, 1:].astype(np.float64) - b[:, 1:]) ** 2)[valid[:, 1:]].mean()
    return float(10 * np.log10(255**2 / mse))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("clips", type=Path)
    p.add_argument("--weathers", default="fog,clear,snow,rain")
    p.add_argument("--per-weather", type=int, default=3)
    p.add_argument("--method", default="profile", choices=["profile", "koschmieder"])
    args = p.parse_args(argv)
    counts: dict[str, int] = {}
    summary: dict[str, list] = {}
    print("clip | beta fitted | ground luma first->last: true, warp, corrected | PSNR warp / corrected")
    for item in load_items(args.clips, None):
        weather = item.tags.get("weather")
        if weather not in args.weathers.split(",") or item.tags.get("time_of_day") != "day":
            continue
        if counts.get(weather, 0) >= args.per_weather:
            continue
        counts[weather] = counts.get(weather, 0) + 1
        vids = item.videos()
        videos = np.stack([vids[c.name] for c in item.rig.cameras])
        wp = np.asarray(item.trajectory_ego, dtype=np.float64)
        poses = poses_from_waypoints(wp, videos.shape[1], item.trajectory_dt_s, item.fps)
        warped, valid = reproject_first_frame(videos, item.rig, poses)
        rel = np.einsum("ij,tjk->tik", invert_T(poses[0]), poses)
        d_t, d_0, _, _ = surface_distances(item.rig, videos.shape[2:4], rel)
        airlight, beta = fit_haze(videos[:, 0], item.rig, d_0[:, 0])
        if args.method == "koschmieder":
            fixed = rehaze(warped, valid, d_t, d_0, airlight, beta)
        else:
            fixed = reshade(warped, valid, item.rig, rel)
        g = [ground_luma(x) for x in (videos, warped, fixed)]
        row = (psnr_valid(warped, videos, valid), psnr_valid(fixed, videos, valid))
        summary.setdefault(weather, []).append(row)
        print(
            f"{weather:6s} {item.key[-22:]} | {beta:.4f} | "
            + "  ".join(f"{x[0]:.0f}->{x[-1]:.0f}" for x in g)
            + f" | {row[0]:.2f} / {row[1]:.2f} dB",
            flush=True,
        )
    for weather, rows in summary.items():
        a, b = np.mean(rows, axis=0)
        print(f"{weather}: PSNR of the warped later frames {a:.2f} dB, corrected {b:.2f} dB ({len(rows)} clips)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
