"""The ego paths of a clip as eval records them (trajectories.json): recovered, logged and conditioned.

All in the first frame's ego frame (x forward, y left, z up; metres for the logged and conditioned
paths, the reconstruction's own scale for the recovered one), so ``eval compare`` can plot a
generator's recovered drive against the trajectory it was conditioned on.
"""

from __future__ import annotations

import numpy as np

from drivewm.geometry import invert_T


def _in_first_frame(T_world_from_ego: np.ndarray) -> np.ndarray:
    """Positions (N, 3) of poses (N, 4, 4) in the ego frame of the first one."""
    T0_inv = invert_T(T_world_from_ego[0])
    return T_world_from_ego[:, :3, 3] @ T0_inv[:3, :3].T + T0_inv[:3, 3]


def ego_paths(item, T_world_from_ego_recovered: np.ndarray, registered: np.ndarray) -> dict:
    """JSON-ready paths of one clip: ``recovered`` (registered frames, their indices in ``recovered_frames``),
    ``reference`` (logged ego poses, when known), ``conditioned`` waypoints (``conditioned_dt_s`` apart,
    from one step after the first frame) and ``fps``."""
    frames = np.flatnonzero(registered)
    out = {"fps": item.fps, "recovered_frames": frames.tolist(), "recovered": []}
    if len(frames):
        out["recovered"] = _in_first_frame(T_world_from_ego_recovered[frames]).tolist()
    if item.T_world_from_ego is not None:
        out["reference"] = _in_first_frame(np.asarray(item.T_world_from_ego)).tolist()
    if item.trajectory_ego:
        out["conditioned"] = [list(map(float, w)) for w in item.trajectory_ego]
        out["conditioned_dt_s"] = item.trajectory_dt_s or 1 / item.fps
    return out
