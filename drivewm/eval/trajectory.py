"""Ego trajectory recovered from video: the camera motion structure from motion finds, as ego poses.

``estimate_ego_trajectory`` reconstructs a clip (or frames + rig) with pycolmap
(drivewm.eval.sfm) and turns the chosen camera's poses into ego poses with its extrinsics,
``T_world_from_ego = T_world_from_cam @ T_ego_from_cam^-1``. The world frame and scale are the
reconstruction's own; align to a reference with drivewm.eval.trajectory_errors (Umeyama with scale).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from drivewm.eval.config import PoseConfig
from drivewm.eval.sfm import SfmResult, run_sfm
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


def ego_from_sfm(sfm: SfmResult, rig: Rig, camera: str = "") -> EgoTrajectory:
    """Ego poses from a reconstruction, through ``camera`` ('' = :func:`forward_camera`)."""
    camera = camera or forward_camera(rig)
    T_cam_from_ego = invert_T(rig.camera(camera).T_ego_from_cam)
    T = sfm.T_world_from_cam[camera] @ T_cam_from_ego
    return EgoTrajectory(T, sfm.registered[camera].copy(), camera)


def estimate_ego_trajectory(clip_or_videos, rig: Rig | Camera | None = None, camera: str = "",
                            cfg: PoseConfig | None = None) -> EgoTrajectory:
    """Camera motion recovered from a clip's frames, as ego poses up to a similarity.

    ``clip_or_videos``: a :class:`drivewm.clips.Clip` (its rig is used when ``rig`` is None), a
    dict of uint8 RGB (T, H, W, 3) per camera name (then ``rig`` is required; one camera is
    enough), or one camera's frames (T, H, W, 3) with ``rig`` that :class:`Camera`.
    """
    if isinstance(rig, Camera):
        rig = Rig(rig.name, [rig])
        if isinstance(clip_or_videos, np.ndarray):
            clip_or_videos = {rig.cameras[0].name: clip_or_videos}
    if isinstance(clip_or_videos, dict):
        videos = clip_or_videos
        if rig is None:
            from drivewm.errors import DrivewmError

            raise DrivewmError("estimate_ego_trajectory: frames given without a rig")
        rig = rig.subset([n for n in rig.names if n in videos])
    else:
        rig = rig or clip_or_videos.meta.get_rig()
        videos = {c: clip_or_videos.video(c) for c in rig.names}
    sfm = run_sfm(videos, rig, cfg or PoseConfig())
    return ego_from_sfm(sfm, rig, camera)
