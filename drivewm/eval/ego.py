"""Ego poses from one camera's recovered motion: ``T_world_from_ego = T_world_from_cam @ T_ego_from_cam^-1``.

Structure from motion (:mod:`drivewm.eval.trajectory`) and dense optical flow
(:mod:`drivewm.eval.flow_motion`) both recover a camera's poses; this is where they become ego poses.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from drivewm.geometry import Camera, Rig, invert_T


@dataclasses.dataclass
class EgoTrajectory:
    """Recovered ``T_world_from_ego`` (T, 4, 4) (NaN where the frame did not register),
    ``registered`` (T,) bool, and the camera it came from."""

    T_world_from_ego: np.ndarray
    registered: np.ndarray
    camera: str


def forward_camera(rig: Rig) -> str:
    """The camera whose optical axis (OpenCV +z) points most along ego +x."""
    return max(rig.cameras, key=lambda c: c.T_ego_from_cam[0, 2]).name


def ego_trajectory(T_world_from_cam: np.ndarray, registered: np.ndarray, camera: Camera) -> EgoTrajectory:
    """Ego poses (T, 4, 4) from the poses of ``camera`` (T, 4, 4) through its extrinsics."""
    return EgoTrajectory(T_world_from_cam @ invert_T(camera.T_ego_from_cam), registered.copy(), camera.name)
