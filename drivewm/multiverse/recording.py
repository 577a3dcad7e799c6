"""One Rerun recording of every future on one timeline (``log_time``, the drives' own clock):

- ``road/KIND``: the road polylines (static);
- ``past/ego``, ``past/agents``: the shared past (ego pose, road users' boxes);
- ``futures/PLAN/ego``, ``futures/PLAN/agents``, ``futures/PLAN/path``: each future under its own
  entity path, plus its whole ego path (static) and its front camera (``futures/PLAN/CAMERA``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drivewm.atomic import atomic_path
from drivewm.logs.viewer import ROAD_COLORS, TIMELINE, _boxes
from drivewm.multiverse.branch import Branch
from drivewm.sim.scene import SceneTick


def write_recording(path: Path, branch: Branch, front: dict[str, tuple[str, list[bytes]]]) -> None:
    """``front``: plan -> (camera name, JPEG bytes per future tick) of the camera to show."""
    import rerun as rr

    with atomic_path(path) as tmp:
        rec = rr.RecordingStream("drivewm_multiverse", recording_id="multiverse")
        rec.set_log_time_enabled(False)  # no wall clock: the same run gives the same recording
        rec.set_log_tick_enabled(False)
        rec.save(str(tmp))
        for line in branch.road.road_lines():
            rec.log(
                f"road/{line.kind}", rr.LineStrips3D([line.points_xyz], colors=[ROAD_COLORS[line.kind]]), static=True
            )
        _log_ticks(rec, rr, "past", branch.past)
        for plan, future in zip(branch.plans, branch.futures):
            base = f"futures/{plan.name}"
            path_xyz = np.stack([t.T_world_from_ego[:3, 3] for t in [branch.past[-1], *future]])
            rec.log(f"{base}/path", rr.LineStrips3D([path_xyz]), static=True)
            _log_ticks(rec, rr, base, future)
            camera, jpegs = front[plan.name]
            for tick, data in zip(future, jpegs):
                rec.set_time(TIMELINE, timestamp=np.datetime64(int(tick.timestamp_ns), "ns"))
                rec.log(f"{base}/{camera}", rr.EncodedImage(contents=data, media_type="image/jpeg"))
        rec.flush()
        rec.disconnect()


def _log_ticks(rec, rr, base: str, ticks: list[SceneTick]) -> None:
    for tick in ticks:
        rec.set_time(TIMELINE, timestamp=np.datetime64(int(tick.timestamp_ns), "ns"))
        T = tick.T_world_from_ego
        rec.log(f"{base}/ego", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
        rec.log(f"{base}/agents", _boxes(tick.agents))
