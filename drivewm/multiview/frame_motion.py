"""Per-frame ego-motion conditioning: where the ego is at every token frame, kept apart from the rays.

Moving-camera rays (``moving_camera_rays``) carry the trajectory inside the per-token Plucker code
that also tells a token where in the rig it looks, so a model can read a turned ray as a token
further round the rig and learn the turn mirrored (a road bending left shows its content where the
straight road shows it further right; drivewm.multiview.trajectory_probe measures this). With
``frame_motion`` the rays stay the static rig's, so a token's place in the rig is never in doubt,
and the ego motion comes as one more embedding per token frame, added to every token of that frame
in every view: the ego pose of the frame in the first frame's ego frame and its motion since the
frame before (as GAIA-2 conditions each frame on the ego's speed and curvature).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from drivewm.geometry import invert_T
from drivewm.multiview.trajectories import poses_from_waypoints

#: Features per token frame: x, y (m / scale), yaw (rad) in the first frame's ego frame, then the
#: step from the frame before in its ego frame: dx, dy (m / step_scale), dyaw (rad / yaw_scale).
FEATURES = 6
STEP_SCALE_M = 5.0
STEP_YAW_RAD = 0.1


def frame_motion_features(
    waypoints_ego: np.ndarray, num_frames: int, dt_s: float, token_fps: float, scale_m: float
) -> np.ndarray:
    """(num_frames, FEATURES) float32 ego motion at each token frame (1 / ``token_fps`` apart) along
    ``waypoints_ego`` (W, 3) spaced ``dt_s``; the first frame's step is its step to the second."""
    poses = poses_from_waypoints(waypoints_ego, max(num_frames, 2), dt_s, token_fps)
    rel = np.einsum("ij,tjk->tik", invert_T(poses[0]), poses)  # frame 0 is the ego frame itself
    yaw = np.arctan2(rel[:, 1, 0], rel[:, 0, 0])
    prev = np.concatenate([[0], np.arange(len(rel) - 1)])
    nxt = np.concatenate([[1], np.arange(1, len(rel))])  # frame 0 looks forward, the others back
    step = np.einsum("tij,tjk->tik", invert_T(rel[prev]), rel[nxt])
    dyaw = np.arctan2(step[:, 1, 0], step[:, 0, 0])
    out = np.stack(
        [
            rel[:, 0, 3] / scale_m,
            rel[:, 1, 3] / scale_m,
            yaw,
            step[:, 0, 3] / STEP_SCALE_M,
            step[:, 1, 3] / STEP_SCALE_M,
            dyaw / STEP_YAW_RAD,
        ],
        axis=1,
    )
    return out[:num_frames].astype(np.float32)


class FrameMotionEncoder(nn.Module):
    """(B, t, FEATURES) -> (B, t, D): Linear -> SiLU -> Linear, the last zero-initialised (a fresh
    encoder leaves its parent model unchanged)."""

    def __init__(self, hidden_dim: int, width: int = 128):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(FEATURES, width), nn.SiLU(), nn.Linear(width, hidden_dim))
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.net(features)
