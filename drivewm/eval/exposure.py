"""Ego poses at each camera's own exposure times, for rigs whose cameras do not fire together.

Real rigs expose their cameras in turn (nuScenes: over ~40 ms as the lidar sweeps past them;
about 40 cm of travel at city speed), so the calibrated F of a camera pair, or of one camera
between frames, must use the ego pose at each image's own exposure time, not at the clip's tick.
Clips carry those times as ``ClipMeta.camera_timestamps_ns`` (absent: every camera at the tick).
The ego poses are logged at the ticks (``timestamps_ns``); between two ticks the pose is
interpolated (translation linear, rotation slerp: drivewm.sim.exposure.interpolate_pose, the
motion model the simulator renders staggered exposures with), beyond the first or last tick it is
extrapolated along the nearest segment.
"""

from __future__ import annotations

import numpy as np

from drivewm.errors import DrivewmError


def ego_at_times(T_world_from_ego: np.ndarray, timestamps_ns: np.ndarray, times_ns: np.ndarray) -> np.ndarray:
    """``T_world_from_ego`` (T, 4, 4) logged at ``timestamps_ns`` (T,) -> poses (N, 4, 4) at ``times_ns`` (N,)."""
    from drivewm.sim.exposure import interpolate_pose  # lazy: drivewm.sim pulls in the simulator's imports

    ts = np.asarray(timestamps_ns, dtype=np.int64)
    if len(ts) < 2 or len(ts) != len(T_world_from_ego) or np.any(np.diff(ts) <= 0):
        raise DrivewmError(
            f"exposure compensation: need >= 2 increasing pose times, got {len(ts)} for {len(T_world_from_ego)} poses"
        )
    out = np.empty((len(times_ns), 4, 4))
    for n, t in enumerate(np.asarray(times_ns, dtype=np.int64)):
        k = int(np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 2))
        w = (t - ts[k]) / (ts[k + 1] - ts[k])  # outside [0, 1]: extrapolated along segment k
        out[n] = T_world_from_ego[k] if w == 0 else interpolate_pose(T_world_from_ego[k], T_world_from_ego[k + 1], w)
    return out


def ego_at_cameras(
    T_world_from_ego: np.ndarray,
    timestamps_ns: list[int],
    camera_timestamps_ns: dict[str, list[int]],
    cameras: list[str],
) -> dict[str, np.ndarray]:
    """Per camera, ``T_world_from_ego`` (T, 4, 4) at its frames' exposure times (cameras without
    their own times are at the tick: the logged poses)."""
    out = {}
    for cam in cameras:
        times = camera_timestamps_ns.get(cam)
        if times is None or list(times) == list(timestamps_ns):
            out[cam] = T_world_from_ego
        elif len(times) != len(T_world_from_ego):
            raise DrivewmError(
                f"exposure compensation: camera {cam} has {len(times)} exposure times "
                f"for {len(T_world_from_ego)} frames"
            )
        else:
            out[cam] = ego_at_times(T_world_from_ego, np.asarray(timestamps_ns), np.asarray(times))
    return out
