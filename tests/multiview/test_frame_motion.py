"""Per-frame ego-motion conditioning (drivewm.multiview.frame_motion): its features follow the
geometry of the waypoints, mirror with them, and enter the model only where a trajectory is kept."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from test_multiview_model import CAPTIONS, _perturb

from drivewm.geometry import load_rig
from drivewm.multiview.config import MultiViewConfig
from drivewm.multiview.frame_motion import STEP_SCALE_M, STEP_YAW_RAD, frame_motion_features
from drivewm.multiview.init import from_text2world
from drivewm.multiview.trajectories import arc_poses, waypoints_from_poses

SPEED, DT, TOKEN_FPS, SCALE = 12.0, 0.1, 2.5, 20.0


def _arc_waypoints(curvature: float, num: int = 24) -> np.ndarray:
    poses = arc_poses(np.arange(num + 1) * SPEED * DT, curvature)
    return waypoints_from_poses(poses, 0, num)


def test_features_of_a_circle_are_its_headings_and_steps():
    kappa = 0.03  # a left turn of 1/33 m: 0.144 rad per 0.4 s token frame at 12 m/s
    f = frame_motion_features(_arc_waypoints(kappa), 5, DT, TOKEN_FPS, SCALE)
    step_yaw = kappa * SPEED / TOKEN_FPS
    # poses_from_waypoints heads along the chord one waypoint ahead: every frame, frame 0 included,
    # leads the arc by the same half step, so headings relative to frame 0 are exact
    np.testing.assert_allclose(f[:, 2], np.arange(5) * step_yaw, atol=2e-3)
    np.testing.assert_allclose(f[:, 5], step_yaw / STEP_YAW_RAD, atol=0.02)
    chord = 2 * np.sin(step_yaw / 2) / kappa  # the step between frames, in the earlier frame's ego frame
    np.testing.assert_allclose(np.hypot(f[:, 3], f[:, 4]) * STEP_SCALE_M, chord, rtol=0.02)
    assert np.all(f[1:, 1] > 0) and np.all(np.diff(f[:, 0]) > 0)  # left of the start, moving forward


def test_a_frame_at_the_end_of_the_waypoints_still_turns():
    """16 waypoints cover 1.6 s, the last token frame's time: it heads along the path's last chord,
    not the frame before's heading (which left the last frame of every turn unturned)."""
    kappa = 0.03
    f = frame_motion_features(_arc_waypoints(kappa, 16), 5, DT, TOKEN_FPS, SCALE)
    step_yaw, lead = kappa * SPEED / TOKEN_FPS, kappa * SPEED * DT / 2  # the chord ahead leads by half a step
    np.testing.assert_allclose(f[:4, 2], np.arange(4) * step_yaw, atol=2e-3)
    np.testing.assert_allclose(f[4, 2], 4 * step_yaw - 2 * lead, atol=2e-3)  # the chord behind trails by half
    assert f[4, 5] > 0.5 * step_yaw / STEP_YAW_RAD


def test_straight_and_mirrored_waypoints():
    straight = frame_motion_features(_arc_waypoints(0.0), 5, DT, TOKEN_FPS, SCALE)
    np.testing.assert_allclose(straight[:, [1, 2, 4, 5]], 0.0, atol=1e-9)
    np.testing.assert_allclose(straight[:, 0], np.arange(5) * SPEED / TOKEN_FPS / SCALE, rtol=1e-6)
    left = _arc_waypoints(0.02)
    a = frame_motion_features(left, 5, DT, TOKEN_FPS, SCALE)
    b = frame_motion_features(left * [1, -1, 1], 5, DT, TOKEN_FPS, SCALE)
    np.testing.assert_allclose(b, a * [1, -1, -1, 1, -1, -1], atol=1e-6)  # the right turn, exactly


def _motion_model(parent):
    return from_text2world(parent, MultiViewConfig(moving_camera_rays=False, frame_motion=True))


def _inputs(model, rig, b=2):
    v = len(rig.cameras)
    caps = [[CAPTIONS[(i + j) % len(CAPTIONS)] for j in range(v)] for i in range(b)]
    traj = np.stack([_arc_waypoints(0.02, 16), _arc_waypoints(-0.02, 16)])
    g = torch.Generator().manual_seed(0)
    x = torch.randn(b * v, *model.latent.latent_shape, generator=g)
    return caps, traj, x, torch.exp(torch.randn(b * v, generator=g))


def test_a_fresh_motion_encoder_changes_nothing_and_static_rays_stay(parent):
    mv = _motion_model(parent)
    rig = load_rig("front3")
    caps, traj, x, sigma = _inputs(mv, rig)
    cond = mv.conditioning(rig, caps, traj)
    assert cond.frame_motion.shape == (6, mv.token_grid()[0], 6)
    torch.testing.assert_close(cond.rays, cond.static_rays)  # the rays say where a token looks, only
    with torch.no_grad():
        torch.testing.assert_close(
            mv.net(x, sigma, cond), mv.net(x, sigma, dataclasses.replace(cond, frame_motion=None))
        )


def test_trained_motion_encoder_tells_the_turns_apart_and_drops_with_the_trajectory(parent):
    mv = _motion_model(parent)
    rig = load_rig("front3")
    caps, traj, x, sigma = _inputs(mv, rig)
    _perturb(mv.net.motion_encoder, 3)
    cond = mv.conditioning(rig, caps, traj)
    mirrored = mv.conditioning(rig, caps, traj * [1, -1, 1])
    no_waypoints = dataclasses.replace(cond, trajectory=None)  # the motion pathway alone
    with torch.no_grad():
        base = mv.net(x, sigma, no_waypoints)
        other = mv.net(x, sigma, dataclasses.replace(mirrored, trajectory=None))
        assert (other - base).abs().mean() > 1e-3 * base.abs().mean()
        free = mv.net(x, sigma, cond.without_trajectory())
        torch.testing.assert_close(free, mv.net(x, sigma, mv.conditioning(rig, caps, None)))


@pytest.mark.parametrize("frames", [1, 3])
def test_features_have_one_row_per_token_frame(frames):
    assert frame_motion_features(_arc_waypoints(0.01), frames, DT, TOKEN_FPS, SCALE).shape == (frames, 6)
