"""Ego trajectory recovered from video: the camera motion structure from motion finds, as ego poses.

``estimate_ego_trajectory`` reconstructs a clip (or frames + rig) with pycolmap
(drivewm.eval.sfm) and turns the chosen camera's poses into ego poses with its extrinsics,
``T_world_from_ego = T_world_from_cam @ T_ego_from_cam^-1``. The world frame and scale are the
reconstruction's own; align to a reference with drivewm.eval.trajectory_errors (Umeyama with scale).
"""

from __future__ import annotations

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.eval.config import PoseConfig
from drivewm.eval.ego import EgoTrajectory, ego_trajectory, forward_camera
from drivewm.eval.flow_motion import flow_ego_trajectory
from drivewm.eval.sfm import SfmResult, run_sfm
from drivewm.geometry import Camera, Rig


def ego_from_sfm(sfm: SfmResult, rig: Rig, camera: str = "") -> EgoTrajectory:
    """Ego poses from a reconstruction, through ``camera`` ('' = :func:`forward_camera`)."""
    camera = camera or forward_camera(rig)
    return ego_trajectory(sfm.T_world_from_cam[camera], sfm.registered[camera], rig.camera(camera))


def estimate_ego_trajectory(
    clip_or_videos,
    rig: Rig | Camera | None = None,
    camera: str = "",
    cfg: PoseConfig | None = None,
    method: str = "sfm",
) -> EgoTrajectory:
    """Camera motion recovered from a clip's frames, as ego poses up to a similarity.

    ``clip_or_videos``: a :class:`drivewm.clips.Clip` (its rig is used when ``rig`` is None), a
    dict of uint8 RGB (T, H, W, 3) per camera name (then ``rig`` is required; one camera is
    enough), or one camera's frames (T, H, W, 3) with ``rig`` that :class:`Camera`.
    ``method``: ``sfm`` (pycolmap), ``flow`` (dense optical flow of the one camera,
    drivewm.eval.flow_motion, for low-resolution generated frames SfM cannot register) or
    ``auto`` (SfM, and flow when SfM leaves frames unregistered: a trajectory with gaps
    cannot be compared over the clip).
    """
    if isinstance(rig, Camera):
        rig = Rig(rig.name, [rig])
        if isinstance(clip_or_videos, np.ndarray):
            clip_or_videos = {rig.cameras[0].name: clip_or_videos}
    if isinstance(clip_or_videos, dict):
        videos = clip_or_videos
        if rig is None:
            raise DrivewmError("estimate_ego_trajectory: frames given without a rig")
        rig = rig.subset([n for n in rig.names if n in videos])
    else:
        rig = rig or clip_or_videos.meta.get_rig()
        videos = {c: clip_or_videos.video(c) for c in rig.names}
    if method not in ("sfm", "flow", "auto"):
        raise DrivewmError(f"estimate_ego_trajectory: method {method!r} is not sfm, flow or auto")
    if method != "flow":
        est = ego_from_sfm(run_sfm(videos, rig, cfg or PoseConfig()), rig, camera)
        if method == "sfm" or est.registered.all():
            return est
    return flow_fallback(videos, rig, camera)


def flow_fallback(videos: dict[str, np.ndarray], rig: Rig, camera: str = "") -> EgoTrajectory:
    """Ego poses from dense optical flow of one camera ('' = :func:`forward_camera`): the fallback
    for frames structure from motion cannot register (drivewm.eval.flow_motion)."""
    camera = camera or forward_camera(rig)
    return flow_ego_trajectory(videos[camera], rig.camera(camera))
