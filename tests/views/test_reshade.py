"""Reshading the reprojection (drivewm.views.reshade): the warp fetches a later frame's road from
further away, and in fog that far road is airlight; with each view's first-frame road profile the
warped road keeps the look the true frames have at its own distance."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.clips import iter_clips
from drivewm.geometry import invert_T, load_rig
from drivewm.multiview.trajectories import poses_from_waypoints
from drivewm.views.reproject import reproject_first_frame
from drivewm.views.reshade import reshade, surface_distances
from drivewm.views.warp import flat_world_points

FPS = 10.0


def ground_luma(videos: np.ndarray) -> np.ndarray:
    """Mean luma of the bottom third of every frame, over the views: (T,)."""
    luma = videos.astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    return luma[:, :, 2 * luma.shape[2] // 3 :].mean(axis=(0, 2, 3))


def relative_poses(wp: np.ndarray, frames: int, dt: float) -> np.ndarray:
    poses = poses_from_waypoints(wp, frames, dt, FPS)
    return np.einsum("ij,tjk->tik", invert_T(poses[0]), poses)


def test_a_road_that_looks_alike_at_every_distance_is_left_as_it_is():
    """Uniform frames: the profile is flat, so mu(d_t) - mu(d_0) is 0 everywhere."""
    rig = load_rig("nuscenes6").scaled(160, 96)
    wp = np.array([[1.5 * (k + 1), 0.0, 0.0] for k in range(8)])  # 15 m/s straight
    videos = np.full((6, 9, 96, 160, 3), (90, 100, 110), np.uint8)
    rel = relative_poses(wp, 9, 0.1)
    valid = np.ones(videos.shape[:4], dtype=bool)
    assert np.array_equal(reshade(videos, valid, rig, rel), videos)
    d_t, d_0, road, lateral = surface_distances(rig, (96, 160), rel)
    front = rig.names.index("CAM_FRONT")
    assert road[front, 8].mean() > 0.3 and np.all(d_0[front, 8][road[front, 8]] > d_t[front, 8][road[front, 8]])
    assert np.allclose(d_t[:, 0][road[:, 0]], d_0[:, 0][road[:, 0]])  # frame 0 is seen from where it is
    assert np.isnan(lateral[front, 0][~np.isfinite(d_t[front, 0])]).all()  # the sky has no place on the road


@pytest.mark.parametrize("size", [(320, 192), (160, 96)])
def test_the_reshading_reads_distances_along_the_warps_own_rays(size):
    """Every pixel's surface is where the warp finds it (warp.flat_world_points): the same rays through
    the same pixel centres, whether the images are the rig's own size or smaller. Rays cast through
    centres half a pixel away (K scaled as if pixel centres sat at half-integers) put the road
    distances 1 % off the warp's at the median, up to 1 m within 20 m and a third or more near the
    horizon."""
    rig = load_rig("nuscenes6").scaled(320, 192)
    w, h = size
    rel = relative_poses(np.array([[1.5 * (k + 1), 0.3 * k, 0.0] for k in range(8)]), 9, 0.1)
    d_t, _, road, _ = surface_distances(rig, (h, w), rel)
    for v, cam in enumerate(rig.cameras):
        for t in (0, 8):
            ground, point, d = flat_world_points(cam, (h, w), rel[t], np.inf)
            o = (rel[t] @ cam.T_ego_from_cam)[:3, 3]
            assert np.array_equal(ground, road[v, t].ravel())
            distance = np.linalg.norm(point[ground] - o, axis=1)
            assert np.allclose(d_t[v, t].ravel()[ground], distance, rtol=1e-9), np.abs(
                d_t[v, t].ravel()[ground] - distance
            ).max()


@pytest.mark.slow
def test_reshading_keeps_a_fog_drives_warped_road_as_the_true_frames_show_it(tmp_path):
    """A simulated fog drive (highway, 320x192), its first frame warped along its own logged path:
    the plain warp pulls the far road's airlight toward the camera, its road brightening by tens of
    levels over 1.6 s (measured 118 -> 191 on a held-out drive) where the true frames stay level;
    reshaded, the last frame's road is within 15 levels of the truth (measured 8) and the warped frames are
    nearer the true ones (measured +7.4 dB on three held-out fog drives at 160x96)."""
    from drivewm.curate import curate, load_curate_config
    from drivewm.sim import SimConfig, simulate

    cfg = SimConfig(rig="nuscenes6", duration_s=2.0, fps=FPS, source="highway", scenario="highway", weather="fog")
    simulate(cfg, tmp_path / "fog.mcap")
    curate([tmp_path / "fog.mcap"], tmp_path / "clips", load_curate_config("test"), executor="local", workers=1)
    clip = next(iter_clips(sorted((tmp_path / "clips").glob("*.tar"))[0]))
    rig = clip.meta.get_rig()
    videos = np.stack([clip.video(n) for n in rig.names])
    wp, dt = np.asarray(clip.meta.trajectory_ego), clip.meta.trajectory_dt_s
    poses = poses_from_waypoints(wp, videos.shape[1], dt, FPS)
    plain, valid = reproject_first_frame(videos, rig, poses)
    fixed, _ = reproject_first_frame(videos, rig, poses, reshade=True)
    assert np.array_equal(fixed[:, 0], plain[:, 0])  # the first frame is its own
    truth, drifted, kept = (ground_luma(v)[-1] for v in (videos, plain, fixed))
    print(f"ground luma of the last frame: true {truth:.0f}, warped {drifted:.0f}, reshaded {kept:.0f}")
    assert drifted - truth > 30 and abs(kept - truth) < 15

    def psnr(out):
        err = (out[:, 1:].astype(np.float64) - videos[:, 1:]) ** 2
        return 10 * np.log10(255**2 / err[valid[:, 1:]].mean())

    print(f"PSNR of the warped later frames: {psnr(plain):.2f} dB, reshaded {psnr(fixed):.2f} dB")
    assert psnr(fixed) > psnr(plain) + 3
