"""The reprojected first frame (drivewm.multiview.warp) on scenes where it is exact (a flat road and
the sky at infinity): a later frame of a moving, turning rig equals the warp of the first frames,
fetched across cameras."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from drivewm.errors import DrivewmError
from drivewm.geometry import T_from_xyz_yaw, load_rig, pixel_rays
from drivewm.multiview.camera import patch_centres_px
from drivewm.multiview.warp import WALL_HEIGHT_M, ray_depths, warp_first_frame, warp_grid

HW = (24, 40)


def sky(d: np.ndarray) -> np.ndarray:
    """A smooth 3-channel pattern on the sphere of directions (N, 3) -> (N, 3)."""
    az, el = np.arctan2(d[:, 1], d[:, 0]), np.arctan2(d[:, 2], np.linalg.norm(d[:, :2], axis=1))
    return np.stack([np.sin(3 * az), np.cos(2 * az + 4 * el), az / np.pi], axis=1)


def road(p: np.ndarray) -> np.ndarray:
    """A smooth 3-channel pattern on the road plane, points (N, 3) with z = 0 -> (N, 3)."""
    return np.stack([np.sin(p[:, 0] / 6.0), np.cos(p[:, 1] / 3.0 + p[:, 0] / 9.0), np.tanh(p[:, 1] / 10.0)], axis=1)


def rig_frame(rig, T_ego0_from_ego: np.ndarray, max_ground_m: float = 0.0) -> torch.Tensor:
    """(V, 3, h, w) latent-resolution image of the rig at pose T: ``road`` where a ray meets the
    road within ``max_ground_m``, else ``sky``."""
    h, w = HW
    out = []
    for cam in rig.cameras:
        T_cam = T_ego0_from_ego @ cam.T_ego_from_cam
        d = pixel_rays(cam.K, patch_centres_px(cam, HW)) @ T_cam[:3, :3].T
        with np.errstate(divide="ignore"):
            depth = np.where(d[:, 2] < 0, -T_cam[2, 3] / d[:, 2], np.inf)
        ground = depth < max_ground_m
        value = sky(d / np.linalg.norm(d, axis=1, keepdims=True))
        value[ground] = road(T_cam[:3, 3] + depth[ground, None] * d[ground])
        out.append(value.T.reshape(3, h, w))
    return torch.from_numpy(np.stack(out)).float()


def test_warp_of_first_frames_is_the_later_frame_at_infinity():
    rig = load_rig("front3")
    poses = np.stack([np.eye(4), T_from_xyz_yaw(5.0, 0.3, 0.0, 0.15), T_from_xyz_yaw(10.0, 1.5, 0.0, 0.45)])
    first = rig_frame(rig, poses[0])
    latents = torch.stack([first, first, first], dim=2)  # (V, 3, T, h, w): only frame 0 is read
    grid, valid = warp_grid(rig, HW, poses, max_ground_m=0.0)  # everything at infinity
    warped = warp_first_frame(latents, grid, valid, num_views=3)
    assert warped.shape == (3, 4, 3, *HW)
    torch.testing.assert_close(warped[:, :3, 0], first, atol=1e-5, rtol=0)  # frame 0 is the identity warp
    for t in (1, 2):
        truth = rig_frame(rig, poses[t])
        m = valid[:, t]
        err = (warped[:, :3, t] - truth).abs().permute(1, 0, 2, 3)[:, m]
        assert m.float().mean() > 0.7
        assert err.mean() < 0.02 and err.max() < 0.25, (t, err.mean(), err.max())  # bilinear error of a smooth pattern
        assert torch.equal(warped[:, 3, t] > 0, m)  # the mask channel
    # A 0.45 rad left turn: the front camera's left part comes from the front-left camera's first frame.
    front = rig.names.index("CAM_FRONT")
    front_only = warp_grid(rig.subset(["CAM_FRONT"]), HW, poses, max_ground_m=0.0)[1][0, 2]
    assert valid[front, 2].float().mean() > 0.95 and front_only.float().mean() < 0.7
    assert not front_only[:, : HW[1] // 3].any()  # alone, the left third was never seen


def test_warp_follows_the_road_plane_as_the_rig_drives():
    rig = load_rig("front3")
    poses = np.stack([np.eye(4), T_from_xyz_yaw(4.0, 0.2, 0.0, 0.1), T_from_xyz_yaw(8.0, 1.0, 0.0, 0.3)])
    first = rig_frame(rig, poses[0], max_ground_m=100.0)
    grid, valid = warp_grid(rig, HW, poses, max_ground_m=100.0)
    warped = warp_first_frame(torch.stack([first] * 3, dim=2), grid, valid, num_views=3)
    grid0, valid0 = warp_grid(rig, HW, poses, 0.0)
    infinity_only = warp_first_frame(torch.stack([first] * 3, dim=2), grid0, valid0, num_views=3)
    for t in (1, 2):
        truth = rig_frame(rig, poses[t], max_ground_m=100.0)
        err = (warped[:, :3, t] - truth).abs().permute(1, 0, 2, 3)[:, valid[:, t]]
        assert valid[:, t].float().mean() > 0.8
        # The road moved under the car and came out where it is: exact up to bilinear interpolation
        # (measured median 0.001-0.002; the mean 0.03-0.06 is the far road, squeezed near the horizon).
        assert err.median() < 0.005 and err.mean() < 0.1, (t, err.median(), err.mean())
        err0 = (infinity_only[:, :3, t] - truth).abs().permute(1, 0, 2, 3)[:, valid0[:, t]]
        assert err0.mean() > 2.5 * err.mean()  # a pure-rotation warp misses the travel (measured 3.2x, 3.9x)


def wall(p: np.ndarray) -> np.ndarray:
    """A smooth 3-channel pattern on the corridor's walls, points (N, 3) with y = +-walls -> (N, 3)."""
    return np.stack([np.sin(p[:, 0] / 5.0), np.cos(p[:, 2] / 2.0 + p[:, 0] / 7.0), np.sign(p[:, 1]) * 0.5], axis=1)


def corridor_frame(rig, T_ego0_from_ego: np.ndarray, walls_m: float) -> torch.Tensor:
    """(V, 3, h, w) image of the rig at pose T in a corridor: the road, two walls at y = +-walls_m of
    the first ego frame up to WALL_HEIGHT_M, whichever a ray meets first within 100 m, else the sky."""
    h, w = HW
    out = []
    for cam in rig.cameras:
        T_cam = T_ego0_from_ego @ cam.T_ego_from_cam
        o, d = T_cam[:3, 3], pixel_rays(cam.K, patch_centres_px(cam, HW)) @ T_cam[:3, :3].T
        with np.errstate(divide="ignore", invalid="ignore"):
            s_road = np.where(d[:, 2] < 0, -o[2] / d[:, 2], np.inf)
            s_wall = (np.where(d[:, 1] >= 0, walls_m, -walls_m) - o[1]) / d[:, 1]
        z = o[2] + s_wall * d[:, 2]
        s_wall = np.where((s_wall > 0) & (z >= 0) & (z <= WALL_HEIGHT_M), s_wall, np.inf)
        value = sky(d / np.linalg.norm(d, axis=1, keepdims=True))
        on_road = (s_road < 100.0) & (s_road <= s_wall)
        on_wall = (s_wall < 100.0) & (s_wall < s_road)
        value[on_road] = road(o + s_road[on_road, None] * d[on_road])
        value[on_wall] = wall(o + s_wall[on_wall, None] * d[on_wall])
        out.append(value.T.reshape(3, h, w))
    return torch.from_numpy(np.stack(out)).float()


def test_ray_depths_meet_the_road_or_the_nearer_wall():
    o = np.array([0.0, 1.0, 1.5])
    d = np.array(
        [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, -0.1], [1.0, 0.0, 0.0], [0.0, 1.0, 3.0], [1.0, 0.2, -0.01]]
    )
    road_only = ray_depths(o, d)
    assert np.isinf(road_only[[0, 1, 3, 4]]).all() and np.isclose(road_only[2], 15.0)
    walled = ray_depths(o, d, walls_m=12.0)
    # left wall 11 m away, right wall 13 m; straight ahead: the road; level ahead: nothing; a ray that
    # clears the wall's top (z = 1.5 + 3 * 11 > 30) goes on to infinity; a shallow one meets the wall
    # (at x = 55 m, 11 m left) before the road (150 m).
    np.testing.assert_allclose(walled[[0, 1, 2, 5]], [11.0, 13.0, 15.0, 55.0])
    assert np.isinf(walled[[3, 4]]).all()


def test_a_corridor_narrower_than_the_rig_is_refused():
    """Walls between the cameras would hide the road from the outer ones: refused by name, before any
    warping; a corridor just wider than the rig, and none at all, are fine."""
    rig = load_rig("nuscenes6")
    widest = max(abs(cam.T_ego_from_cam[1, 3]) for cam in rig.cameras)
    assert widest == 0.5  # the side cameras sit half a metre off the centre line
    poses = np.stack([np.eye(4), T_from_xyz_yaw(4.0, 0.0, 0.0, 0.0)])
    with pytest.raises(DrivewmError, match="outside it"):
        warp_grid(rig, HW, poses, walls_m=0.5 * widest)
    for walls in (0.0, 1.01 * widest):
        _, valid = warp_grid(rig, HW, poses, walls_m=walls)
        assert valid[:, 1].float().mean() > 0.5


def test_warp_with_walls_moves_the_roadside_by_its_parallax():
    """In a corridor, the walled warp reproduces the later frames where the flat-world warp leaves the
    walls at infinity (studies/warp_walls.py)."""
    rig = load_rig("front3")
    poses = np.stack([np.eye(4), T_from_xyz_yaw(4.0, 0.2, 0.0, 0.1), T_from_xyz_yaw(8.0, 1.0, 0.0, 0.3)])
    first = corridor_frame(rig, poses[0], 12.0)
    latents = torch.stack([first] * 3, dim=2)
    errors = {}
    for walls in (12.0, 0.0):
        grid, valid = warp_grid(rig, HW, poses, max_ground_m=100.0, walls_m=walls)
        warped = warp_first_frame(latents, grid, valid, num_views=3)
        for t in (1, 2):
            truth = corridor_frame(rig, poses[t], 12.0)
            assert valid[:, t].float().mean() > 0.8
            errors[walls, t] = (warped[:, :3, t] - truth).abs().permute(1, 0, 2, 3)[:, valid[:, t]]
    for t in (1, 2):  # measured: median 0.003 / 0.005; mean 0.04 / 0.06 walled against 0.16 / 0.28 flat
        assert errors[12.0, t].median() < 0.01, (t, errors[12.0, t].median())
        assert errors[0.0, t].mean() > 2.0 * errors[12.0, t].mean(), (t, errors[0.0, t].mean(), errors[12.0, t].mean())


def test_a_warp_conditioned_model_renders_with_its_corridor(mv_parent_dir):
    """``multiview.warp_walls_m`` reaches the training warp (``clip_warp_grids``, behind
    ``warp_condition`` and ``warped_noise``): the first latent frame maps onto itself either way, and
    later frames fetch the roadside from elsewhere than with the flat world."""
    from drivewm.diffusion.text2world import Text2World
    from drivewm.multiview.init import from_text2world
    from drivewm.multiview.model import clip_warp_grids
    from drivewm.multiview.posttrain import posttrain_config
    from drivewm.multiview.trajectories import resolve_trajectory

    grids = {}
    for walls in (0.0, 25.0):
        cfg = posttrain_config("debug", [f"multiview.warp_walls_m={walls}"])
        model = from_text2world(Text2World.from_pretrained(mv_parent_dir), cfg.multiview, cfg.cond_frames)
        mv = model.cfg.multiview
        assert mv.warp_walls_m == walls
        wp = resolve_trajectory("straight", mv.trajectory_waypoints, mv.trajectory_dt_s, 15.0)
        grids[walls] = clip_warp_grids(model, load_rig("front3"), wp[None], 10.0)
    flat, walled = grids[0.0][0], grids[25.0][0]
    torch.testing.assert_close(walled[:, 0], flat[:, 0])  # frame 0 is the identity warp either way
    moved = (walled[:, 1:] - flat[:, 1:]).abs().amax(-1) > 1e-3
    assert moved.any() and not moved.all()  # the roadside moves, the road and sky do not


def test_warp_reaches_the_model_only_with_its_trajectory():
    """The warp feeds the tokens through a zero-initialised projection; a dropped trajectory drops it."""
    import dataclasses

    from drivewm.diffusion.dit_config import DiTConfig
    from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
    from drivewm.multiview.init import from_text2world
    from drivewm.multiview.trajectories import resolve_trajectory

    torch.manual_seed(0)
    parent = Text2World(
        Text2WorldConfig(DiTConfig(in_channels=3, hidden_dim=32, depth=1, num_heads=2, adaln_lora_dim=8)),
        LatentInfo([3, 3, 8, 12], [0.0] * 3, [0.5] * 3, 10.0, None, {}),
    )
    with torch.no_grad():  # as after pre-training: zero-initialised output layers are not zero any more
        for p in parent.dit.parameters():
            p.add_(0.05 * torch.randn_like(p))
    from drivewm.multiview.config import MultiViewConfig

    mv = from_text2world(parent, MultiViewConfig(warp_condition=True), cond_frames=1)
    rig = load_rig("front3")
    cond = mv.conditioning(rig, [["a road"] * 3], resolve_trajectory("left", 16, 0.1, 10.0)[None])
    x = torch.randn(3, 3, 3, 8, 12)
    cond = dataclasses.replace(cond, cond_latents=torch.randn(3, 3, 3, 8, 12), cond_frames=1)
    sigma = torch.full((3,), 2.0)
    with torch.no_grad():
        fresh = mv.net(x, sigma, cond)
        torch.testing.assert_close(
            fresh, mv.net(x, sigma, dataclasses.replace(cond, warp_grid=None))
        )  # zero init: no effect yet
        torch.nn.init.normal_(mv.net.warp_encoder.proj.weight, std=0.5)
        used = mv.net(x, sigma, cond)
        free = mv.net(x, sigma, cond.without_trajectory())
        no_warp_free = mv.net(x, sigma, dataclasses.replace(cond.without_trajectory(), warp_grid=None))
    assert (used - fresh).abs().mean() > 1e-2
    torch.testing.assert_close(free, no_warp_free)


@pytest.mark.slow  # post-trains from the tiny Text2World parent on the stand-in tokenizer's clips
def test_warp_lr_scale_trains_the_warp_projection_faster_and_resumes_exactly(mv_latents, mv_parent_dir, tmp_path):
    """``warp_lr_scale`` is the warp projection's own learning-rate multiplier (a parameter group of
    the shared loop): 0 leaves it at zero while the rest trains, 10 moves it about ten times as far
    as 1, and a run stopped and resumed equals one that went through."""
    from drivewm.multiview.posttrain import posttrain, posttrain_config

    base = ["rig=front3", "train.steps=4", "train.log_every=1", "train.checkpoint_every=2", "train.warmup_steps=2"]
    base += ["sample_steps=1", "trajectory_probe_every=0", "multiview.warp_condition=true"]
    base += ["multiview.video2world_prob=1.0"]  # every step gives the first frame: the warp has a gradient

    def raw(name: str, scale: float, stop_after: int | None = None) -> dict[str, torch.Tensor]:
        cfg = posttrain_config("debug", [*base, f"warp_lr_scale={scale}"])
        posttrain(cfg, mv_parent_dir, mv_latents, tmp_path / name, stop_after=stop_after)
        return torch.load(tmp_path / name / "train_state.pt", weights_only=True)["model"]

    def warp_max(state: dict[str, torch.Tensor]) -> float:
        return float(state["warp_encoder.proj.weight"].abs().max())

    one, frozen, fast = raw("one", 1.0), raw("frozen", 0.0), raw("fast", 10.0)
    assert warp_max(frozen) == 0.0 and warp_max(one) > 0
    from drivewm.diffusion.text2world import Text2World

    parent = Text2World.from_pretrained(mv_parent_dir).dit.state_dict()["final.proj.weight"]
    assert not torch.equal(frozen["denoiser.backbone.final.proj.weight"], parent)  # the rest trained
    assert 5.0 < warp_max(fast) / warp_max(one) < 20.0, (warp_max(fast), warp_max(one))
    raw("resumed", 10.0, stop_after=2)
    resumed = raw("resumed", 10.0)
    assert all(torch.equal(fast[k], resumed[k]) for k in fast)
